"""The output folder of a run, checked (and created) before anything is solved."""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import tempfile
from pathlib import Path

from coils._files import replacing as _replacing

from .tables import SceneError

__all__ = ["prepare_output_dir", "replacing", "write_json", "write_rows", "save_figure"]


def _nearest_existing(path: Path) -> Path:
    anc = path
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    return anc


def prepare_output_dir(path: str | Path, *, create: bool = True, key: str = "--out") -> Path:
    """Make sure the results can be written to the folder ``path``.

    Parameters
    ----------
    path : str or Path
        The output folder; it may not exist yet.
    create : bool
        Create the folder (and its parents) and try writing a file in it (True), or only check
        that it could be created and written (False: nothing on disk changes).
    key : str
        The name of the setting, for the message (the CLI option ``--out``).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    SceneError
        One line naming ``key``, the folder and the reason: an existing file, a parent that is
        a file, no permission to create or write.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as root:
    ...     prepare_output_dir(pathlib.Path(root) / "results" / "run1").is_dir()
    True
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SceneError(
            f"{key}: {path} is an existing file, not a folder; give a folder (new or existing) "
            "for the results"
        )
    anc = _nearest_existing(path)
    if not anc.is_dir():
        raise SceneError(f"{key}: cannot create the folder {path}: {anc} is a file")
    if not create:
        if not os.access(anc, os.W_OK | os.X_OK):
            what = "write in" if anc == path else "create folders in"
            raise SceneError(f"{key}: cannot {what} {anc} (permission denied)")
        return path
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SceneError(
            f"{key}: cannot create the folder {path} ({exc.strerror or type(exc).__name__})"
        ) from None
    try:
        with tempfile.NamedTemporaryFile(dir=path, prefix=".coilrod-write-test-"):
            pass
    except OSError as exc:
        raise SceneError(
            f"{key}: cannot write in {path} ({exc.strerror or type(exc).__name__})"
        ) from None
    return path


@contextlib.contextmanager
def replacing(path: str | Path):
    """Write the file ``path`` whole or not at all (:func:`coils._files.replacing`).

    Yields a temporary file name next to ``path`` (with its suffix); when the block ends
    without an error, it replaces ``path`` at once; on an error it is removed and ``path`` is
    as before.

    Raises
    ------
    SceneError
        One line naming ``path`` if it cannot be written (no permission, a folder there, a
        full disk, the folder removed).
    """
    try:
        with _replacing(path) as tmp:
            yield tmp
    except OSError as exc:
        raise SceneError(str(exc)) from None


def _finite(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: Path, data) -> Path:
    """Write ``data`` as indented JSON to ``path`` (whole or not at all, see :func:`replacing`);
    non-finite floats are written as null (strict JSON has no NaN or Infinity).  Returns
    ``path``."""
    text = json.dumps(_finite(data), indent=2, allow_nan=False)
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_rows(path: Path, rows: list[dict]) -> Path:
    """Write ``rows`` (dicts with the same keys, in order) to the CSV file ``path`` with a
    header line from the first row's keys; no rows give an empty file.  The file is written
    whole or not at all (see :func:`replacing`).  Returns ``path``."""
    with replacing(path) as tmp, tmp.open("w", newline="", encoding="utf-8") as fh:
        if rows:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return path


def save_figure(fig, path: Path) -> Path:
    """Save the matplotlib figure ``fig`` to ``path`` (PNG at 120 dpi, tight), whole or not at
    all (see :func:`replacing`).  Returns ``path``."""
    with replacing(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight")
    return path
