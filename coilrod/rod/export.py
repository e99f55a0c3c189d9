"""Rod centrelines to VTK for ParaView: one polyline per state, with the arc length and the
cross-section frames as point data, and a ParaView collection (.pvd) over the load path."""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from coils._files import replacing_together

__all__ = ["write_vtk"]

_EXTENSIONS = (".vtu", ".vtk")


def _states(result, states) -> list[int]:
    n = len(result)
    if states is None:
        return list(range(n))
    many = np.ndim(states) > 0
    idx = np.atleast_1d(np.asarray(states))
    if idx.dtype.kind not in "iu":
        raise ValueError(f"states must be integers; got {states!r}")
    out = []
    for k in idx.tolist():
        if not -n <= k < n:
            raise ValueError(f"state {k} out of range: the result has {n} states")
        out.append(k % n)
    return out if many else out[:1]


def write_vtk(result, path, states=None, *, frames: bool = True) -> list[Path]:
    """Write rod centrelines as VTK polylines (meshio).

    Parameters
    ----------
    result : RodResult or RodPath
        Anything with ``s`` (n,) m, ``len()``, ``centerline(k)`` (n, 3) m and ``frames(k)``
        (n, 3, 3) (columns: tangent, normal, binormal).
    path : str or Path
        Target file, ``.vtu`` or ``.vtk``.  One state (an int ``states``) is written there; a
        sequence of states (default: all) to ``stem_000.vtu``, ``stem_001.vtu``, ... next to
        it, plus ``stem.pvd``, a ParaView collection whose time steps are the load scales (or
        the state indices).
    states : int or sequence of int, optional
    frames : bool
        Add the tangent, normal and binormal vectors as point data.

    Returns
    -------
    list of Path
        The files written (the .pvd last).

    Raises
    ------
    ValueError
        A bad extension or state.
    OSError
        The directory or a file cannot be written (the message names it).  The files are
        written all or none (temporary files, renamed together when every one is written: an
        error part way leaves no state's file, and existing files as they were); a symbolic
        link is written through.
    """
    import meshio

    path = Path(path)
    if path.suffix.lower() not in _EXTENSIONS:
        raise ValueError(f"path must end in .vtu or .vtk; got {str(path)!r}")
    single = states is not None and np.ndim(states) == 0
    rows = _states(result, states)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise OSError(f"cannot write VTK files: {str(folder)!r} is not a directory")
    if not os.access(folder, os.W_OK):
        raise OSError(f"cannot write VTK files: the directory {str(folder)!r} is not writable")
    s = np.asarray(result.s, float)
    written = []
    scales = getattr(result, "scales", None)
    if scales is None:
        scales = getattr(result, "scale", None)
    with replacing_together() as replacing:  # every file or none (an error removes them)
        for k in rows:
            pts = np.asarray(result.centerline(k), float)
            cells = [("line", np.column_stack([np.arange(len(pts) - 1), np.arange(1, len(pts))]))]
            data = {"s": s}
            if frames:
                R = np.asarray(result.frames(k), float)
                data.update(tangent=R[:, :, 0], normal=R[:, :, 1], binormal=R[:, :, 2])
            mesh = meshio.Mesh(pts, cells, point_data=data)
            target = path if single else path.with_name(f"{path.stem}_{k:03d}{path.suffix}")
            with replacing(target) as tmp:  # whole; OSError naming target
                mesh.write(tmp)
            written.append(target)
        if not single:
            pvd = path.with_suffix(".pvd")
            lines = [
                '<?xml version="1.0"?>',
                '<VTKFile type="Collection" version="0.1">',
                "<Collection>",
            ]
            for k, target in zip(rows, written, strict=True):
                time = float(scales[k]) if scales is not None else float(k)
                lines.append(
                    f'<DataSet timestep="{time!r}" part="0" file={quoteattr(target.name)}/>'
                )
            lines += ["</Collection>", "</VTKFile>", ""]
            with replacing(pvd) as tmp:
                tmp.write_text("\n".join(lines), encoding="utf-8")
            written.append(pvd)
    return written
