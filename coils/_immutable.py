"""Immutable objects: a field source or an obstacle is fixed when its constructor returns.

A coil's field is computed from arrays derived once from its parameters (filaments, the
compiled kernel's data), an obstacle's gap from its pieces and bounding volumes; an attribute
that could be assigned afterwards would disagree with the numbers the object returns.  So the
classes that opt in (``_immutable = True``) are sealed at the end of construction:

* assigning or deleting any attribute raises ``AttributeError`` saying how to change it
  (``with_current``, ``with_currents``, ``replace``);
* every ndarray attribute is made read-only (``writeable=False``), so ``pair.center[0] = 1``
  raises ``ValueError: assignment destination is read-only``;
* :meth:`Immutable.replace` returns a changed copy: the constructor (or the preset function
  that built the object, see :func:`remembers_recipe`) called again with the same parameters
  except those given, so the copy is validated like any new object and equals one built
  directly with those parameters.

Lazily built internal caches (the compiled kernel's arguments, a system's unit channels) are
derived from the sealed data only, start as None in the constructor and are set with
:meth:`Immutable._set_cache`; a pickled or evolved copy gets them as None and rebuilds them on
first use.  Subclasses of :class:`coils.Field` or :class:`coilrod.contact.Obstacle` written by
users are not sealed unless they opt in.
"""

from __future__ import annotations

import functools
import inspect

import numpy as np

__all__ = ["Immutable", "kernel_input", "remembers_recipe", "sealed"]

#: Longest repr of a value shown in an "is immutable" message.
_SHOW = 40


def kernel_input(value, dtype=float) -> np.ndarray:
    """``value`` as a read-only C-contiguous ndarray of ``dtype`` for a compiled kernel's input.

    numba compiles one version of a kernel per argument layout, and read-only and writable
    arrays are different layouts: an input made read-only here (a view, no copy, when
    ``value`` already is C-contiguous of ``dtype``) gives one compiled version whether the
    caller's array is sealed (:func:`sealed`) or not.
    """
    arr = np.ascontiguousarray(value, dtype=dtype)
    if arr.flags.writeable:
        arr = arr.view()
        arr.flags.writeable = False
    return arr


def sealed(value, dtype=float) -> np.ndarray:
    """A read-only copy of ``value`` as an ndarray of ``dtype`` (never a view of the caller's)."""
    arr = np.array(value, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


_PLAIN = frozenset({float, int, str, bool, type(None)})


def _snapshot(value):
    """A parameter as stored for :meth:`Immutable.replace`: arrays as read-only copies and lists
    as tuples (recursively), so later changes to the caller's objects do not leak in."""
    kind = type(value)
    if kind in _PLAIN:
        return value
    if kind is np.ndarray:
        arr = value.copy()
        arr.setflags(write=False)
        return arr
    if kind is list or kind is tuple:
        return tuple(_snapshot(v) for v in value)
    if isinstance(value, np.ndarray):
        return _snapshot(np.asarray(value))
    return value


def _reseal(value) -> None:
    """Make the arrays of a snapshotted parameter read-only again (after unpickling)."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, tuple):
        for v in value:
            _reseal(v)


def _show(value) -> str:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    text = repr(value)
    return text if len(text) <= _SHOW else "..."


@functools.cache
def _layout(func) -> tuple[tuple[str, ...], int, dict, bool]:
    """Parameter names of ``func`` (in order, ``*args`` and ``**kwargs`` left out), how many
    can be given by position, their defaults, and whether it takes ``**kwargs``."""
    names, defaults, n_positional, var_keyword = [], {}, 0, False
    for p in inspect.signature(func).parameters.values():
        if p.kind is p.VAR_KEYWORD:
            var_keyword = True
        elif p.kind is not p.VAR_POSITIONAL:
            names.append(p.name)
            n_positional += p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
            if p.default is not p.empty:
                defaults[p.name] = p.default
    return tuple(names), n_positional, defaults, var_keyword


def _parameters(func, args, kwargs) -> dict | None:
    """The arguments of a successful call ``func(*args, **kwargs)`` by parameter name, defaults
    included, snapshotted; None if some went to ``*args`` (they have no name to replace)."""
    names, n_positional, defaults, _ = _layout(func)
    if len(args) > n_positional:
        return None
    given = dict(zip(names, args, strict=False))
    given.update(kwargs)
    params = {name: given[name] if name in given else defaults[name] for name in names}
    params.update((k, v) for k, v in kwargs.items() if k not in params)  # **kwargs
    return {name: _snapshot(v) for name, v in params.items()}


def _sealing(init):
    """Wrap a constructor so that the outermost call seals the object it built."""

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        state = self.__dict__
        if state.get("_frozen", False):
            raise AttributeError(
                f"{type(self).__name__} is immutable: it cannot be initialised again; build a "
                f"new one or use .replace(...)"
            )
        outermost = "_constructing" not in state
        if outermost:
            state["_constructing"] = True
        try:
            init(self, *args, **kwargs)
        finally:
            if outermost:
                del state["_constructing"]
        if outermost and type(self)._immutable:
            params = _parameters(init, (self, *args), kwargs)
            if params is not None:
                del params[next(iter(params))]  # self
            self._seal(params)

    __init__._seals = True
    return __init__


class Immutable:
    """Mixin of objects sealed at the end of construction (see :mod:`coils._immutable`).

    Subclasses set ``_immutable = True`` to opt in (inherited by their subclasses); their
    ``__init__`` is wrapped so that the outermost constructor call seals the object.
    """

    #: Seal instances when construction ends.
    _immutable: bool = False
    #: Lazily built caches (None until first use): reset to None when pickled or evolved.
    _caches: tuple[str, ...] = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get("__init__")
        if init is not None and not getattr(init, "_seals", False):
            cls.__init__ = _sealing(init)

    # -- sealing -----------------------------------------------------------------------------------
    def _seal(self, params: dict | None, builder=None) -> None:
        """Make the ndarray attributes read-only, remember the construction parameters (None:
        unknown) and the function that builds the object, if not its class, for
        :meth:`replace`, and forbid assignment from now on."""
        state = self.__dict__
        for value in state.values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
        state["_params"] = params
        state["_builder"] = builder
        state["_frozen"] = True

    def _set_cache(self, name: str, value) -> None:
        """Store a lazily built cache derived from the sealed data (names in ``_caches``)."""
        if name not in self._caches:  # pragma: no cover - a programming error
            raise AttributeError(f"{name!r} is not a cache of {type(self).__name__}")
        self.__dict__[name] = value

    def _how_to_change(self, name: str, value) -> str:
        """The hint of the "is immutable" message for an assignment ``name = value``."""
        params = self.__dict__.get("_params") or {}
        if name in params:
            return f"use .replace({name}={_show(value)}) for a changed copy"
        listed = ", ".join(params)
        return "build a new one" + (
            f" or use .replace(...) for a changed copy (its parameters: {listed})" if listed else ""
        )

    def __setattr__(self, name: str, value) -> None:
        if self.__dict__.get("_frozen", False):
            raise AttributeError(
                f"{type(self).__name__} is immutable (its results are computed from the values "
                f"it was built with): cannot set {name!r}; {self._how_to_change(name, value)}"
            )
        object.__setattr__(self, name, value)

    def __delattr__(self, name: str) -> None:
        if self.__dict__.get("_frozen", False):
            raise AttributeError(
                f"{type(self).__name__} is immutable: cannot delete {name!r}; build a new one"
            )
        object.__delattr__(self, name)

    # -- copies ------------------------------------------------------------------------------------
    def replace(self, **changes):
        """A copy with some construction parameters changed (like ``dataclasses.replace``).

        Parameters
        ----------
        **changes
            New values of parameters of the constructor (or of the preset function that built
            this object, e.g. ``coilrod.contact.presets.bend``), by name.

        Returns
        -------
        The same kind of object, built anew from this one's parameters with ``changes``
        applied and validated as any new object (this one is unchanged).

        Raises
        ------
        ValueError
            If a name is not a parameter (the message lists them), or a new value is invalid.

        Examples
        --------
        >>> from coils import HelmholtzPair
        >>> pair = HelmholtzPair(radius=0.08, turns=200, current=6.7, axis="y")
        >>> wider = pair.replace(radius=0.1, current=3.35)
        >>> wider.radius, wider.current, pair.radius, pair.current
        (0.1, 3.35, 0.08, 6.7)
        """
        params = self.__dict__.get("_params")
        if params is None:
            raise ValueError(
                f"this {type(self).__name__} was not built by a constructor or a preset that "
                f"records its parameters by name; build a new one instead of .replace()"
            )
        build = self.__dict__.get("_builder") or type(self)
        unknown = [name for name in changes if name not in params]
        if unknown and not _layout(build.__init__ if isinstance(build, type) else build)[3]:
            raise ValueError(
                f"{type(self).__name__}.replace got an unknown parameter {unknown[0]!r}; its "
                f"parameters are {', '.join(params)}"
            )
        return build(**{**params, **changes})

    def _evolve(self, params: dict, **attributes):
        """A sealed shallow copy with ``attributes`` set (arrays sealed) and caches dropped:
        for fast copies such as ``with_current`` whose new attributes are exactly those a
        construction with ``params`` would give."""
        new = object.__new__(type(self))
        state = new.__dict__
        state.update(self.__dict__)
        for name in self._caches:
            state[name] = None
        for name, value in attributes.items():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            state[name] = value
        state["_params"] = params
        return new

    # -- pickling ----------------------------------------------------------------------------------
    def __getstate__(self):
        state = dict(self.__dict__)
        for name in self._caches:
            state[name] = None
        return state

    def __setstate__(self, state) -> None:
        # unpickled and deep-copied arrays come back writeable: seal them again
        self.__dict__.update(state)
        if state.get("_frozen", False):
            for value in state.values():
                if isinstance(value, np.ndarray):
                    value.setflags(write=False)
            for value in (state.get("_params") or {}).values():
                _reseal(value)


def remembers_recipe(func):
    """Decorate a preset function returning an :class:`Immutable` object: the object's
    :meth:`~Immutable.replace` then takes the preset's parameters and calls it again."""

    @functools.wraps(func)
    def preset(*args, **kwargs):
        obj = func(*args, **kwargs)
        obj.__dict__["_params"] = _parameters(func, args, kwargs)
        obj.__dict__["_builder"] = preset
        return obj

    return preset
