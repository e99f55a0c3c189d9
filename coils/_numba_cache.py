"""Numba's on-disk cache and the ski rental of every compiled kernel.

Every compiled kernel of :mod:`coils` and :mod:`coilrod` runs a numpy twin until compiling
pays (README "Cold start"), except when numba's cache already holds the compiled code
(loading it costs ~0.1 s): :class:`Rental` keeps that account, :func:`on_disk` looks at the
cache, and :func:`guard` makes every kernel's cache entries fail safe (a damaged one is a
warning and a recompile).  This module does not import numba: it reads the cache path a
dispatcher carries, and guards numba's kernels once numba is imported.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.abc
import importlib.util
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


#: Appended to every data file (``.nbc``) numba writes for a guarded kernel: this marker, then
#: the SHA-256 of the pickle before it.  ``pickle.loads`` stops at the pickle's end, so numba
#: without the guard (an older coilrod in the same cache) still reads such a file.
_SEAL = b"\0coilrod-sha256:"
_SEAL_LEN = len(_SEAL) + 32
#: Top-level packages whose kernels are guarded when numba defines them (:func:`guard`).
_PACKAGES = ("coils", "coilrod")


def _discard(path: Path, what: str, name: str, reason: str, cache=None) -> None:
    """Warn that numba's cache ``what`` (index or data file) of kernel ``name`` at ``path``
    is damaged (``reason``) and remove it; where it cannot be removed, ``cache`` (numba's
    per-kernel cache object) is disabled for this process."""
    try:
        path.unlink(missing_ok=True)
        done = "removed it; the kernel compiles anew and numba writes a fresh one"
    except OSError as exc:
        getattr(cache, "disable", lambda: None)()
        done = f"cannot remove it ({exc.strerror or exc}); numba's cache is off for {name}"
    warnings.warn(
        f"numba's cache {what} of {name} {str(path)!r} is damaged ({reason}); {done}",
        RuntimeWarning,
        stacklevel=4,
    )


def _unseal(raw: bytes) -> tuple[bytes | None, str | None]:
    """The pickle of a data file's contents ``raw`` if its seal checks (``_SEAL``), else
    ``(None, reason)``: ``reason`` is None for an intact file written without a seal (by numba
    unguarded: nothing vouches for its machine code, so the kernel compiles anew, without a
    warning), else why the file is damaged."""
    if raw[-_SEAL_LEN:-32] == _SEAL:
        body = raw[:-_SEAL_LEN]
        if hashlib.sha256(body).digest() == raw[-32:]:
            return body, None
        return None, "its SHA-256 does not match the one written with it"
    try:
        pickle.loads(raw)
    except Exception as exc:  # noqa: BLE001 -- any unpickling error: what numba would raise
        return None, f"{type(exc).__name__}: {exc}"
    return None, None


@functools.cache
def _guarded_types() -> tuple[type, type]:
    """numba's per-kernel cache and cache-file classes with the guard (imports numba)."""
    from numba.core import caching

    class GuardedFile(caching.IndexDataCacheFile):
        """numba's index and data files of one kernel, sealed and checked (:func:`guard`)."""

        _kernel_name = "a kernel"

        def _load_index(self):
            try:
                return super()._load_index()
            except Exception as exc:  # noqa: BLE001 -- numba catches only a missing index
                _discard(Path(self._index_path), "index", self._kernel_name, _reason(exc))
                return {}

        def _load_data(self, name):
            path = Path(self._data_path(name))
            body, reason = _unseal(path.read_bytes())  # OSError: numba's own "no entry"
            if body is None:
                if reason is not None:
                    _discard(path, "data file", self._kernel_name, reason)
                return None
            return pickle.loads(body)

        def _save_data(self, name, data):
            body = self._dump(data)
            with self._open_for_write(self._data_path(name)) as fh:
                fh.write(body + _SEAL + hashlib.sha256(body).digest())

    class GuardedCache(caching.FunctionCache):
        """numba's cache of one kernel: an entry it cannot rebuild is a miss (:func:`guard`)."""

        def _load_overload(self, sig, target_context):
            try:
                return super()._load_overload(sig, target_context)
            except Exception as exc:  # noqa: BLE001 -- whatever rebuilding the entry raised
                key = self._index_key(sig, target_context.codegen())
                name = self._cache_file._load_index().get(key)
                if name is None:  # not from a cache entry: numba's own error
                    raise
                path = Path(self._cache_file._data_path(name))
                _discard(path, "data file", self._cache_file._kernel_name, _reason(exc), self)
                return None

    return GuardedCache, GuardedFile


def _reason(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def guard(dispatcher) -> None:
    """Make numba's on-disk cache of ``dispatcher`` (a ``numba.njit(cache=True)`` function)
    fail safe: a damaged index or data file (truncated, garbled, unreadable by numba or not
    rebuildable) is removed with a RuntimeWarning and the kernel compiles anew (numba's own
    loader raises from inside the call), and each data file numba writes is sealed with its
    SHA-256, so that a changed byte of machine code is never run (a data file without the
    seal, written by numba unguarded, is compiled anew without a warning).  Every kernel of
    :mod:`coils` and :mod:`coilrod` is guarded when numba defines it (:func:`_install`);
    a dispatcher without numba's default cache is left alone.  Compiles nothing."""
    cache = getattr(dispatcher, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if cache_file is None:
        return
    try:
        GuardedCache, GuardedFile = _guarded_types()
    except (ImportError, AttributeError):  # numba internals changed: numba's own cache
        return
    if type(cache) in (GuardedCache.__base__, GuardedCache):
        cache.__class__ = GuardedCache
    if type(cache_file) in (GuardedFile.__base__, GuardedFile):
        cache_file.__class__ = GuardedFile
        cache_file._kernel_name = getattr(dispatcher, "__name__", "a kernel")


def _ours(dispatcher) -> bool:
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""
    return module.partition(".")[0] in _PACKAGES


def _install(dispatcher_module) -> None:
    """Guard (:func:`guard`) every cached kernel of :mod:`coils` and :mod:`coilrod`: those
    defined from now on (numba's ``Dispatcher.enable_caching``, which ``njit(cache=True)``
    calls, is wrapped; other packages' kernels are left as numba makes them) and those
    defined already."""
    try:
        dispatcher_class = dispatcher_module.Dispatcher
        enable = dispatcher_class.enable_caching
    except AttributeError:  # numba internals changed: numba's own cache
        return
    if getattr(enable, "_coils_guard", False):
        return

    def enable_caching(self):
        enable(self)
        if _ours(self):
            guard(self)

    enable_caching._coils_guard = True
    dispatcher_class.enable_caching = enable_caching
    for name, module in list(sys.modules.items()):
        if module is not None and name.partition(".")[0] in _PACKAGES:
            for value in list(vars(module).values()):
                if isinstance(value, dispatcher_class) and _ours(value):
                    guard(value)


class _AfterNumba(importlib.abc.MetaPathFinder):
    """Calls :func:`_install` once numba's dispatcher module is imported (this module does
    not import numba: importing :mod:`coils` stays quick)."""

    _NAME = "numba.core.dispatcher"

    def find_spec(self, fullname, path, target=None):
        if fullname != self._NAME:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is not None and spec.loader is not None:
            loader = spec.loader
            run = loader.exec_module

            def exec_module(module):  # (a loader may serve other modules too)
                run(module)
                if module.__name__ == self._NAME:
                    _install(module)

            loader.exec_module = exec_module
        return spec


if _AfterNumba._NAME in sys.modules:
    _install(sys.modules[_AfterNumba._NAME])
elif not any(isinstance(f, _AfterNumba) for f in sys.meta_path):
    sys.meta_path.insert(0, _AfterNumba())


def _check_index(dispatcher) -> None:
    """Before ``dispatcher`` (a ``numba.njit(cache=True)`` function) first compiles or loads:
    if its index in numba's cache is damaged, remove it with a warning (:func:`guard`: the
    kernel compiles anew); guards ``dispatcher`` if not yet.  Compiles nothing."""
    guard(dispatcher)
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if hasattr(cache_file, "_kernel_name"):
        cache_file._load_index()


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
        from then on.  Callers that compile anyway call :meth:`buy`.
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
            self.buy()
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
            self.buy()

    def buy(self) -> None:
        """The compiled kernel runs from now on (:meth:`pays` calls it when compiling pays; a
        caller that runs the compiled kernel anyway calls it too); a damaged cache index is
        removed first (:func:`_check_index`)."""
        _check_index(self._kernel())
        self.ready = True
