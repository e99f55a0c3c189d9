"""Input files: one clear error naming the file for a missing, unreadable or non-UTF-8 file.

The errors are both the matching :class:`OSError` subclass and :class:`ValueError` (what the
readers have always documented), so ``except FileNotFoundError`` and ``except ValueError`` both
catch a missing file.
"""

from __future__ import annotations

import codecs
import contextlib
import os
import tempfile
from pathlib import Path

__all__ = [
    "replacing",
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


@contextlib.contextmanager
def replacing(path):
    """Write the file ``path`` whole or not at all.

    Yields a temporary file name next to ``path`` (with its suffix, for writers that read the
    format from it).  When the block ends without an error, that file replaces ``path`` at
    once (an existing file is overwritten, never left half-written); on an error it is removed
    and ``path`` is as before.

    Raises
    ------
    OSError
        Of the class of the failure (PermissionError, IsADirectoryError, FileNotFoundError,
        ...), its message naming ``path``.
    """
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}-", suffix=path.suffix)
        os.close(fd)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 -> what open() would have given
    except OSError as exc:
        raise _write_error(path, exc) from None
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        raise _write_error(path, exc) from None
    finally:
        Path(tmp).unlink(missing_ok=True)
