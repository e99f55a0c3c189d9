"""The CSV file of a sweep: one row per finished point, appended and flushed as it finishes, read
back to resume, and rewritten in grid order when every point is done.

Numbers are written with ``repr`` (the shortest text that reads back as the same float), so a
row read back from the file equals the row that was written, and a resumed sweep's file equals an
uninterrupted one's.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import numbers
from pathlib import Path

import numpy as np

from ..scene.outputs import replacing
from ..scene.parse import SceneError

__all__ = ["SweepFile", "SceneFingerprint", "format_cell", "parse_cell"]

#: How the cells of each kind of column are read back.
KINDS = ("int", "number", "bool", "text")


def format_cell(value) -> str:
    """The CSV text of one value: "" for None, True/False, ``repr`` of floats (exact)."""
    if value is None:
        return ""
    if isinstance(value, bool | np.bool_):
        return "True" if value else "False"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    return " ".join(str(value).split())  # text on one line


def parse_cell(text: str, kind: str):
    """The value of one CSV cell of a column of ``kind`` (raises ValueError if it is not one).

    Examples
    --------
    >>> parse_cell("0.06", "number"), parse_cell("200", "number"), parse_cell("", "bool")
    (0.06, 200, None)
    """
    if kind == "text":
        return text
    if text == "":
        if kind == "int":
            raise ValueError("empty point number")
        return None
    if kind == "bool":
        if text not in ("True", "False"):
            raise ValueError(f"expected True or False; got {text!r}")
        return text == "True"
    if kind == "int":
        return int(text)
    try:
        return int(text)
    except ValueError:
        return float(text)


class SweepFile:
    """``DIR/sweep.csv`` of one sweep.

    Parameters
    ----------
    path : Path
        The CSV file.
    columns : list of str
        Its header.
    kinds : dict
        Column -> one of "int" (the point number, first column), "number", "bool", "text".
    """

    def __init__(self, path: Path, columns: list[str], kinds: dict[str, str]):
        self.path = Path(path)
        self.columns = list(columns)
        self.kinds = kinds
        self._keep = 0  # bytes of the existing file to keep (header and whole rows)
        #: Whether :meth:`check` kept an existing file's header (and rows) to append to.
        self.resumes = False
        self._fh = None

    # -- reading back ------------------------------------------------------------------------
    def check(self, *, resume: bool, overwrite: bool) -> dict[int, dict]:
        """What an existing file holds, before anything is written or solved.

        Returns the rows already in the file (point -> row) when resuming, else nothing.

        Raises
        ------
        SceneError
            The file is a folder or cannot be read; it exists and neither ``resume`` nor
            ``overwrite`` is given; its header is not this sweep's; a row other than the last
            cannot be read (a cut last line is what a killed sweep leaves: it is dropped).
        """
        path = self.path
        if path.is_dir():
            raise SceneError(f"{path}: is a folder; the sweep writes its table there")
        if not path.exists():
            return {}
        if not resume:
            if overwrite:
                return {}
            raise SceneError(
                f"{path}: exists (an earlier sweep); give --resume (resume=True) to continue "
                "it, --overwrite (overwrite=True) to replace it, or another folder"
            )
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise SceneError(
                f"{path}: cannot read the sweep's table ({exc.strerror or type(exc).__name__})"
            ) from None
        lines = raw.splitlines(keepends=True)
        if not lines or not lines[0].endswith(b"\n"):
            if self._line({c: c for c in self.columns}).encode("utf-8").startswith(raw):
                return {}  # killed before the header was complete: start again
            raise SceneError(
                f"{path}: not a sweep's table (its first line is not a header and not the "
                "start of one); use another folder, or overwrite it"
            )
        try:
            header = self._record(lines[0].removeprefix(b"\xef\xbb\xbf"))
        except ValueError as exc:
            raise SceneError(f"{path}: line 1 is not a sweep's header ({exc})") from None
        if header != self.columns:
            raise SceneError(f"{path}: from another sweep: {_difference(header, self)}")
        rows: dict[int, dict] = {}
        keep = len(lines[0])
        for number, line in enumerate(lines[1:], start=2):
            last = number == len(lines)
            try:
                if not line.endswith(b"\n"):
                    raise ValueError("the line is cut short")
                row = self._row(line)
            except ValueError as exc:
                if last:  # what a sweep killed while writing leaves: solve that point again
                    break
                raise SceneError(
                    f"{path}: line {number} is damaged ({exc}); remove the line or start the "
                    "sweep again"
                ) from None
            if row["point"] in rows:
                raise SceneError(
                    f"{path}: line {number} repeats point {row['point']}; remove one of the two "
                    "rows"
                )
            rows[row["point"]] = row
            keep += len(line)
        self._keep = keep
        self.resumes = True
        return rows

    def _record(self, line: bytes) -> list[str]:
        try:
            text = line.decode("utf-8")
        except UnicodeDecodeError:
            raise ValueError("not UTF-8 text") from None
        try:
            return next(csv.reader([text.rstrip("\r\n")]), [])
        except csv.Error as exc:  # e.g. a NUL byte
            raise ValueError(str(exc)) from None

    def _row(self, line: bytes) -> dict:
        cells = self._record(line)
        if len(cells) != len(self.columns):
            raise ValueError(f"{len(cells)} cells, the header has {len(self.columns)}")
        row = {}
        for col, text in zip(self.columns, cells, strict=True):
            try:
                row[col] = parse_cell(text, self.kinds[col])
            except ValueError as exc:
                raise ValueError(f"column {col}: {exc}") from None
        return row

    # -- writing -----------------------------------------------------------------------------
    def open(self) -> None:
        """Start writing: a new file with its header, or the existing one cut after its last
        whole row (see :meth:`check`)."""
        if self._keep:
            with self.path.open("r+b") as fh:
                fh.truncate(self._keep)
            self._fh = self.path.open("a", newline="", encoding="utf-8")
        else:
            self._fh = self.path.open("w", newline="", encoding="utf-8")
            self._fh.write(self._line({c: c for c in self.columns}))
            self._fh.flush()

    def append(self, row: dict) -> None:
        """Append one row and flush it (a sweep killed afterwards keeps it)."""
        self._fh.write(self._line(row))
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def rewrite(self, rows: list[dict]) -> None:
        """Replace the file by ``rows`` (in their order) at once (a temporary file, renamed);
        :meth:`open` then appends to it."""
        self.close()
        with replacing(self.path) as tmp, tmp.open("w", newline="", encoding="utf-8") as fh:
            fh.write(self._line({c: c for c in self.columns}))
            fh.writelines(self._line(r) for r in rows)
        self._keep = self.path.stat().st_size

    def _line(self, row: dict) -> str:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(
            [format_cell(row.get(c)) for c in self.columns]
        )
        return buf.getvalue()


def _difference(header: list[str], file: SweepFile) -> str:
    ours = file.columns
    missing = [c for c in ours if c not in header]
    extra = [c for c in header if c not in ours]
    if not missing and not extra:
        return "the same columns in another order; use another folder or overwrite it"
    parts = []
    if extra:
        parts.append(f"it has {', '.join(extra)}")
    if missing:
        parts.append(f"this sweep writes {', '.join(missing)}")
    return "; ".join(parts) + " (other parameters or models?); use another folder or overwrite it"


def _coilrod_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("coilrod")
    except PackageNotFoundError:  # pragma: no cover - a source tree that is not installed
        return "unknown"


def _canonical(data) -> str:
    """Canonical JSON of parsed TOML data: sorted keys, no spaces (dates as their text)."""
    return json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str)


def _differences(old, new, key: str = "") -> list[str]:
    """The keys at which two JSON values differ, with both values."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new), key=str):
            sub = f"{key}.{k}" if key else str(k)
            if k not in old:
                out.append(f"{sub} is new ({_canonical(new[k])})")
            elif k not in new:
                out.append(f"{sub} was removed (it was {_canonical(old[k])})")
            else:
                out += _differences(old[k], new[k], sub)
        return out
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        out = []
        for i, (a, b) in enumerate(zip(old, new, strict=True)):
            out += _differences(a, b, f"{key}.{i}" if key else str(i))
        return out
    if _canonical(old) == _canonical(new):
        return []
    return [f"{key or 'the scene'} was {_canonical(old)}, now {_canonical(new)}"]


class SceneFingerprint:
    """``DIR/sweep.json`` next to ``DIR/sweep.csv``: which scene and coilrod version wrote the
    rows, so that a resumed sweep does not keep the rows of another scene.

    The file holds ``coilrod_version``, ``scene_sha256`` (SHA-256 of the canonical JSON of the
    scene's parsed TOML data: sorted keys, no whitespace, so comments and layout of the scene
    file do not count) and ``scene`` (that data, to name what changed).

    Parameters
    ----------
    path : Path
        The JSON file.
    data : dict
        The scene's TOML data (``Scene.data``, before the swept values are put in).
    """

    def __init__(self, path: Path, data: dict):
        self.path = Path(path)
        text = _canonical(data)
        self.record = {
            "coilrod_version": _coilrod_version(),
            "scene_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
            "scene": json.loads(text),
        }

    def check(self, table: Path) -> None:
        """Refuse to resume the rows of ``table`` unless this file says they are this scene's,
        computed by this coilrod version.

        Raises
        ------
        SceneError
            The file is missing or unreadable, or names another coilrod version or another
            scene (the keys that differ, with both values).
        """
        fix = "use another folder or overwrite it"
        try:
            old = json.loads(self.path.read_text(encoding="utf-8"))
            if not isinstance(old, dict):
                raise ValueError("not a JSON object")
        except FileNotFoundError:
            raise SceneError(
                f"{self.path}: missing, so the scene the rows of {table} were solved for is "
                f"unknown; {fix}"
            ) from None
        except (OSError, ValueError) as exc:
            raise SceneError(
                f"{self.path}: cannot read the scene fingerprint of {table} ({exc}); {fix}"
            ) from None
        ours = self.record
        if old.get("coilrod_version") != ours["coilrod_version"]:
            raise SceneError(
                f"{table}: solved by coilrod {old.get('coilrod_version')}, this is coilrod "
                f"{ours['coilrod_version']} (the rows may differ); {fix}"
            )
        if old.get("scene_sha256") != ours["scene_sha256"]:
            changed = _differences(old.get("scene"), ours["scene"]) or ["the scene content"]
            raise SceneError(
                f"{table}: solved for another scene (scene content differs: "
                f"{'; '.join(changed)}); {fix}"
            )

    def write(self) -> None:
        """Write the file at once (a temporary file, renamed)."""
        with replacing(self.path) as tmp, tmp.open("w", encoding="utf-8") as fh:
            json.dump(self.record, fh, sort_keys=True, indent=1, ensure_ascii=False)
            fh.write("\n")
