"""Whether numba's on-disk cache holds a kernel's compiled code: the ski rentals' probe.

Every compiled kernel of :mod:`coils` and :mod:`coilrod` runs a numpy twin until compiling
pays (README "Cold start"), except when numba's cache already holds the compiled code
(loading it costs ~0.1 s).  This module does not import numba: it only reads the cache path
a dispatcher carries.
"""

from __future__ import annotations

from pathlib import Path

_seen: dict = {}  # dispatcher -> whether its cache index was on disk at the first look


def on_disk(dispatcher) -> bool:
    """Whether numba's cache held compiled code of ``dispatcher`` (a ``numba.njit`` function
    with ``cache=True``) when this process first asked.  The disk is looked at once per
    kernel and process: the callers ask on every call until they compile, and a cache another
    process writes later is not noticed (the ski rental then runs its course)."""
    seen = _seen.get(dispatcher)
    if seen is None:
        try:
            seen = Path(dispatcher._cache._cache_file._index_path).exists()
        except AttributeError:  # numba internals changed: assume not
            seen = False
        _seen[dispatcher] = seen
    return seen
