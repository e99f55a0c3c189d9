"""Numba's on-disk cache and the ski rental of every compiled kernel.

Every compiled kernel of :mod:`coils` and :mod:`coilrod` runs a numpy twin until compiling
pays (README "Cold start"), except when numba's cache already holds the compiled code
(loading it costs ~0.1 s): :class:`Rental` keeps that account, :func:`on_disk` looks at the
cache.  This module does not import numba: it only reads the cache path a dispatcher carries.
"""

from __future__ import annotations

import hashlib
import pickle
import sys
import warnings
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


def tie_to_sources(dispatcher, *paths) -> None:
    """Make numba's on-disk cache of ``dispatcher`` (a ``numba.njit(cache=True)`` function)
    stale when any file of ``paths`` changes, not only its own: numba checks only the
    defining file's contents (its index's "source stamp"), but a kernel compiled with helpers
    of another module holds their code too.  The stamp becomes ``(numba's own stamp, sha256 of
    the files' contents)``: numba's loader then treats an index written before either file
    changed as empty, compiles anew and overwrites it.  Call it where the kernel is defined
    (before its first call); reads the files, compiles nothing.  Where the stamp cannot be
    set (numba internals changed) or a file cannot be read, the cache is off for this kernel
    (a stale kernel would be worse than compiling)."""
    h = hashlib.sha256()
    try:
        for path in paths:
            h.update(Path(path).read_bytes())
        cache_file = dispatcher._cache._cache_file
        cache_file._source_stamp = (cache_file._source_stamp, h.hexdigest())
    except (OSError, AttributeError):
        try:
            from numba.core.caching import NullCache

            dispatcher._cache = NullCache()
        except (ImportError, AttributeError):  # pragma: no cover - numba without NullCache
            pass


def _check_index(dispatcher) -> None:
    """Before ``dispatcher`` (a ``numba.njit(cache=True)`` function) first compiles or loads:
    if its index in numba's cache is damaged (numba's own loader would raise from inside the
    call: it catches only a missing file), remove it with a warning, so that the kernel
    compiles anew and numba writes a fresh index.  Where it cannot be removed, the cache is
    off for this kernel in this process.  Reads the index as numba does (a pickled version,
    then, for this numba's version, the pickled stamp and overloads); compiles nothing."""
    try:
        cache = dispatcher._cache
        path, version = Path(cache._cache_file._index_path), cache._cache_file._version
    except AttributeError:  # not cached, or numba internals changed: nothing to check
        return
    try:
        with open(path, "rb") as fh:
            found = pickle.load(fh)
            rest = fh.read()
        if found == version:  # another version's index is ignored by numba, not read
            pickle.loads(rest)
        return
    except FileNotFoundError:
        return
    except Exception as exc:  # noqa: BLE001 -- any unpickling error: what numba would raise
        reason = f"{type(exc).__name__}: {exc}"
    name = getattr(dispatcher, "__name__", "a kernel")
    try:
        path.unlink()
        done = "removed it; the kernel compiles anew and numba writes a fresh one"
    except OSError as exc:
        getattr(cache, "disable", lambda: None)()
        done = f"cannot remove it ({exc.strerror or exc}); numba's cache is off for {name}"
    warnings.warn(
        f"numba's cache index of {name} {str(path)!r} is damaged ({reason}); {done}",
        RuntimeWarning,
        stacklevel=3,
    )


class Rental:
    """The ski rental of one compiled kernel in this process: run its numpy twin (rent) while
    the numpy calls' estimated cost stays within the price of compiling, then the compiled
    kernel (buy) for good.

    Parameters
    ----------
    owner : str
        Name of the module that holds the threshold (``__name__`` of the caller).
    kernel : callable
        ``kernel()`` returns the ``numba.njit(cache=True)`` dispatcher; called only when the
        cache is asked about or the compiled kernel is about to run (so the module that
        compiles it is imported no earlier).
    threshold : str
        Name of the owner's attribute holding the price: the estimated CPU seconds of numpy
        calls after which the compiled kernel runs (0 compiles at the first call,
        ``math.inf`` never).  Read at each decision, so that setting ``module.COMPILE_AFTER``
        (tests, benchmarks) takes effect at once.
    in_process : bool
        Also buy when the dispatcher has compiled code in this process already (its
        ``overloads``).

    Attributes
    ----------
    spent : float
        Estimated CPU seconds of the numpy calls charged so far (:meth:`charge`).
    ready : bool
        True once compiling has paid (:meth:`pays` returned True): the compiled kernel runs
        from then on.  Callers that compile anyway set it.
    """

    def __init__(self, owner: str, kernel, threshold: str = "COMPILE_AFTER", in_process=False):
        self._owner, self._kernel, self._threshold = owner, kernel, threshold
        self._in_process = in_process
        self.spent = 0.0
        self.ready = False

    @property
    def threshold(self) -> float:
        """The price (s of CPU): the owner module's threshold attribute, read now."""
        return getattr(sys.modules[self._owner], self._threshold)

    def held(self) -> bool:
        """Whether compiling costs nothing: numba's cache held the kernel at this process's
        first look (:func:`on_disk`), or (``in_process``) it is compiled in this process."""
        kernel = self._kernel()
        return bool(self._in_process and kernel.overloads) or on_disk(kernel)

    def pays(self, seconds: float = 0.0) -> bool:
        """True if the compiled kernel should run the next call, whose numpy twin would cost
        an estimated ``seconds`` of CPU (0 where the cost is known only afterwards and is
        charged then): it is ready, or the numpy calls charged so far have cost the price or
        would with this one cost more, or the kernel is :meth:`held` (asked only if not).  A
        True is for good (:attr:`ready`); after a False the caller runs the numpy twin and
        :meth:`charge` s it."""
        if not self.ready:
            price = self.threshold
            if self.spent < price and self.spent + seconds <= price and not self.held():
                return False
            self._buy()
        return True

    def rent(self, seconds: float) -> bool:
        """:meth:`pays` for a call whose numpy twin would cost an estimated ``seconds`` of CPU,
        and if not, that cost :meth:`charge` d: True runs the compiled kernel, False the numpy
        twin (the caller's two branches)."""
        if self.pays(seconds):
            return True
        self.charge(seconds)
        return False

    def charge(self, seconds: float) -> None:
        """Add the estimated CPU seconds of one numpy call to :attr:`spent`."""
        self.spent += seconds

    def expect(self, seconds: float) -> None:
        """Announce numpy calls to come of an estimated ``seconds`` of CPU in all (a known
        horizon): if with them the rent would cost more than the price, the compiled kernel
        runs from the next call on (compiling once is cheaper than renting to the end).
        The cache is not asked (:meth:`pays` does at the next call)."""
        if not self.ready and self.spent + seconds > self.threshold:
            self._buy()

    def _buy(self) -> None:
        """The compiled kernel runs from now on; a damaged cache index is removed first
        (:func:`_check_index`: numba would raise from inside the first call)."""
        _check_index(self._kernel())
        self.ready = True
