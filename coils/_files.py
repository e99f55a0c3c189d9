"""Input files: one clear error naming the file for a missing, unreadable or non-UTF-8 file.

The errors are both the matching :class:`OSError` subclass and :class:`ValueError` (what the
readers have always documented), so ``except FileNotFoundError`` and ``except ValueError`` both
catch a missing file.
"""

from __future__ import annotations

import codecs
import contextlib
import errno
import os
import tempfile
from pathlib import Path

__all__ = [
    "replacing",
    "replacing_together",
    "MissingFileError",
    "NotAFileError",
    "UnreadableFileError",
    "input_path",
    "read_text",
    "read_utf8",
]


class MissingFileError(FileNotFoundError, ValueError):
    """An input file that does not exist."""


class NotAFileError(IsADirectoryError, ValueError):
    """An input path that is a folder (or another non-file), not a file."""


class UnreadableFileError(PermissionError, ValueError):
    """An input file that exists but cannot be read (permissions, an I/O error)."""


def input_path(path, label: str) -> str:
    """``path`` as a str, checked to be an existing regular file.

    Parameters
    ----------
    path : str or os.PathLike
    label : str
        What the file is, for the messages (e.g. ``"mesh file"``).

    Raises
    ------
    ValueError
        ``path`` is not a str or path-like.
    MissingFileError, NotAFileError
        It does not exist, or it is a folder.
    """
    if not isinstance(path, str | os.PathLike):
        raise ValueError(f"path must be a file name (str or path-like); got {path!r}")
    path = os.fspath(path)
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if os.path.isdir(path):
        raise NotAFileError(f"cannot read the {label} {path!r}: it is a folder, not a file")
    if not os.path.exists(path):
        raise MissingFileError(f"cannot read the {label} {path!r}: it does not exist")
    if not os.path.isfile(path):
        raise NotAFileError(f"cannot read the {label} {path!r}: it is not a regular file")
    return path


def read_utf8(
    path,
    *,
    unreadable: str,
    not_utf8: str,
    unreadable_error: type[Exception] = UnreadableFileError,
    not_utf8_error: type[Exception] = ValueError,
    label: str = "file",
) -> str:
    """The UTF-8 text of the file ``path`` (a leading byte-order mark dropped), errors worded by
    the caller.

    The one reader of the file readers here and of the scene files
    (:func:`coilrod.scene.parse.load_scene`), which word their errors differently.

    Parameters
    ----------
    path : str or os.PathLike
        The file (not checked to exist first: a missing file is an unreadable one).
    unreadable : str
        The message when the file cannot be opened or read, a :meth:`str.format` template with
        the fields ``path``, ``label`` and ``reason`` (the system's reason, e.g. ``"Permission
        denied"``).
    not_utf8 : str
        The message when the bytes are not UTF-8, a template with the fields ``path``,
        ``label``, ``byte`` (the first bad byte, e.g. ``"0xe9"``) and ``line`` (its line, from 1).
    unreadable_error, not_utf8_error : type
        The exception classes of the two cases (each called with the message alone).
    label : str
        What the file is (the ``label`` field of the templates).

    Raises
    ------
    unreadable_error, not_utf8_error
        With the messages above.
    """
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise unreadable_error(unreadable.format(path=path, label=label, reason=reason)) from None
    if raw.startswith(codecs.BOM_UTF8):
        raw = raw[len(codecs.BOM_UTF8) :]  # so that exc.start below counts in these bytes
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        byte = f"0x{raw[exc.start]:02x}"
        raise not_utf8_error(
            not_utf8.format(path=path, label=label, byte=byte, line=line)
        ) from None


def read_text(path, label: str) -> str:
    """The UTF-8 text of the file ``path`` (a leading byte-order mark dropped).

    Raises
    ------
    MissingFileError, NotAFileError, UnreadableFileError
        It does not exist, is a folder, or cannot be read.
    ValueError
        It is not UTF-8 text (the message names the byte and its line).
    """
    return read_utf8(
        input_path(path, label),
        unreadable="cannot read the {label} {path!r} ({reason})",
        not_utf8="{label} {path!r} is not UTF-8 text (byte {byte} on line {line}); "
        "is it a binary or damaged file? Save it as UTF-8 text",
        label=label,
    )


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _write_error(path: Path, exc: OSError) -> OSError:
    """``exc``'s class (PermissionError, IsADirectoryError, ...) with a message naming ``path``."""
    return type(exc)(f"cannot write {str(path)!r} ({exc.strerror or exc})")


def _through_link(path: Path) -> Path:
    """Where writing ``path`` goes: the file a symbolic link at ``path`` points to (written
    through, as ``open(path, "w")`` would, not replaced by a regular file), else ``path``."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _temporary(target: Path, shown: Path) -> Path:
    """An empty temporary file next to ``target`` (with its suffix, for writers that read the
    format from it), of the mode ``open()`` would give; errors name ``shown``."""
    try:
        if target.is_dir():  # found now, before anything is written, not at the rename
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR))
        fd, tmp = tempfile.mkstemp(
            dir=target.parent, prefix=f".{target.stem}-", suffix=target.suffix
        )
        os.close(fd)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 -> what open() would have given
    except OSError as exc:
        raise _write_error(shown, exc) from None
    return Path(tmp)


def _publish(staged: list[tuple[Path, Path, Path]]) -> None:
    """Rename each written temporary file onto its target; if a rename fails, remove the
    targets this call created (files it replaced already keep their new content)."""
    created = []
    for tmp, target, shown in staged:
        existed = os.path.lexists(target)
        try:
            os.replace(tmp, target)
        except OSError as exc:
            for done in created:
                done.unlink(missing_ok=True)
            raise _write_error(shown, exc) from None
        if not existed:
            created.append(target)


@contextlib.contextmanager
def replacing_together():
    """Write several files all or none.

    Yields ``replacing(path)``, a context manager like :func:`replacing` whose file is
    published only when this block ends without an error, together with the others (each
    renamed onto its target).  On an error in the block every temporary file is removed and no
    target has changed; if a rename fails (after every file was written), the targets this
    call created are removed too (those it replaced already keep their new content).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as root:
    ...     with replacing_together() as replacing:
    ...         for name in ("a.txt", "b.txt"):
    ...             with replacing(pathlib.Path(root) / name) as tmp:
    ...                 _ = tmp.write_text(name)
    ...     sorted(p.name for p in pathlib.Path(root).iterdir())
    ['a.txt', 'b.txt']
    """
    staged: list[tuple[Path, Path, Path]] = []

    @contextlib.contextmanager
    def one(path):
        shown = Path(path)
        target = _through_link(shown)
        tmp = _temporary(target, shown)
        staged.append((tmp, target, shown))
        try:
            yield tmp
        except OSError as exc:
            raise _write_error(shown, exc) from None

    try:
        yield one
        _publish(staged)
    finally:
        for tmp, _, _ in staged:
            tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def replacing(path):
    """Write the file ``path`` whole or not at all.

    Yields a temporary file name next to ``path`` (with its suffix, for writers that read the
    format from it).  When the block ends without an error, that file replaces ``path`` at
    once (an existing file is overwritten, never left half-written; a symbolic link is written
    through: the file it points to is replaced, the link kept); on an error it is removed and
    ``path`` is as before.  Several files all or none: :func:`replacing_together`.

    Raises
    ------
    OSError
        Of the class of the failure (PermissionError, IsADirectoryError, FileNotFoundError,
        ...), its message naming ``path``.
    """
    with replacing_together() as one, one(path) as tmp:
        yield tmp
