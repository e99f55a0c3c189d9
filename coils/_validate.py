"""One place for input validation: the public API of :mod:`coils` (and the robot description in
:mod:`coilrod.robot`) checks its arguments with these helpers and nothing else.

Each helper returns the value in canonical form (a float, an int, a float ndarray, a unit vector)
or raises ``ValueError`` whose message names the argument, says what it must be and shows what
it got: ``"points must have shape (n, 3); got (3, 2)"``, ``"turns must be a real number; got
'200'"``.

What counts as a number
-----------------------
Real numbers are Python ``int`` and ``float``, numpy integer and floating scalars, 0-d arrays of
those and other :class:`numbers.Real` (``Fraction``); arrays are arrays or (nested) sequences of
them.  Refused everywhere, even where Python or numpy would convert them:

* strings and bytes, also when they spell a number (``"1"``): text is not a quantity (scene files
  parse units, :mod:`coilrod.scene.units`; the library takes numbers);
* booleans (``True`` is not one turn nor one metre), also inside a sequence (``(True, 0, 0)``);
* complex numbers (numpy would drop the imaginary part).

Kinds of argument and their helpers
-----------------------------------
=====================  ========================================================================
real scalars           :func:`finite_scalar`, :func:`positive`, :func:`nonnegative`
counts                 :func:`as_count` (one), :func:`as_counts` (a fixed-length tuple)
arrays of reals        :func:`as_array` (any shape), :func:`as_vector` (shape (k,)),
                       :func:`as_points` (shape (n, 3), a single point promoted),
                       :func:`as_triple` (a scalar or 3 values, e.g. grid spacings),
                       :func:`as_limits` (a scalar or one positive bound per entry, inf allowed)
directions             :func:`as_axis` ("x", "-y", or a non-zero 3-vector, normalised)
flags and options      :func:`as_bool`, :func:`as_choice`
objects                :func:`coils.field.as_field` (a :class:`coils.Field`; it lives with
                       the class, so that this module imports nothing of coils)
=====================  ========================================================================
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence

import numpy as np

__all__ = [
    "finite_scalar",
    "positive",
    "nonnegative",
    "as_count",
    "as_counts",
    "as_array",
    "as_vector",
    "as_points",
    "as_triple",
    "as_limits",
    "as_axis",
    "as_bool",
    "as_choice",
]

_TEXT = (str, bytes, bytearray)
_FLAGS = (bool, np.bool_)
#: Longest repr of a bad value shown in a message.
_SHOW = 80


def _show(value) -> str:
    """``repr(value)`` for a message, cut to a readable length."""
    text = repr(value)
    return text if len(text) <= _SHOW else text[: _SHOW - 4] + " ..."


# -- real scalars -------------------------------------------------------------------------------
def finite_scalar(value, name: str) -> float:
    """Return ``value`` as a finite float.

    Parameters
    ----------
    value : real number
        An ``int``, ``float``, numpy integer or floating scalar, 0-d array of those, or another
        real number (``Fraction``, ``Decimal``); not a string, bytes, boolean or complex number.
    name : str
        The argument's name, for the message.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        "NAME must be a real number; got '1'", "NAME must be a scalar; got shape (2,)",
        "NAME must be finite; got nan".

    Examples
    --------
    >>> finite_scalar(np.float32(2.5), "current")
    2.5
    >>> finite_scalar("2.5", "current")
    Traceback (most recent call last):
    ...
    ValueError: current must be a real number; got '2.5'
    """
    if isinstance(value, np.ndarray):
        if value.ndim != 0:
            raise ValueError(f"{name} must be a scalar; got shape {value.shape}")
        value = value[()]
    if isinstance(value, _TEXT + _FLAGS):
        raise ValueError(f"{name} must be a real number; got {_show(value)}")
    if not isinstance(value, numbers.Real) and isinstance(value, np.generic | numbers.Complex):
        raise ValueError(f"{name} must be a real number; got {_show(value)}")
    try:
        val = float(value)
    except OverflowError:
        raise ValueError(f"{name} must be finite; got {_show(value)}") from None
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number; got {_show(value)}") from None
    if not math.isfinite(val):
        raise ValueError(f"{name} must be finite; got {val}")
    return val


def positive(value, name: str) -> float:
    """Return ``value`` as a finite float > 0 ("NAME must be positive; got 0.0")."""
    val = finite_scalar(value, name)
    if val <= 0:
        raise ValueError(f"{name} must be positive; got {val}")
    return val


def nonnegative(value, name: str) -> float:
    """Return ``value`` as a finite float >= 0 ("NAME must be >= 0; got -1.0")."""
    val = finite_scalar(value, name)
    if val < 0:
        raise ValueError(f"{name} must be >= 0; got {val}")
    return val


# -- counts -------------------------------------------------------------------------------------
def as_count(value, name: str, minimum: int = 1, maximum: int | None = None) -> int:
    """Return ``value`` as an int in ``[minimum, maximum]``.

    Integral floats (``4.0``) and numpy integers are accepted; booleans, fractions, NaN,
    infinities and strings are not.  The message names the argument: "samples must be an
    integer >= 2; got 1", "n_axial must be a positive integer; got 0", "axis must be an integer
    from 0 to 2; got 3".

    Examples
    --------
    >>> as_count(4.0, "samples", 2)
    4
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if maximum is not None:
        what = f"an integer from {minimum} to {maximum}"
    else:
        what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
    if isinstance(value, _FLAGS) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {what}; got {_show(value)}")
    if isinstance(value, numbers.Integral):
        count = int(value)
    else:
        as_float = float(value)
        if not math.isfinite(as_float) or not as_float.is_integer():
            raise ValueError(f"{name} must be {what}; got {_show(value)}")
        count = int(as_float)
    if count < minimum or (maximum is not None and count > maximum):
        raise ValueError(f"{name} must be {what}; got {_show(value)}")
    return count


def as_counts(value, name: str, parts: Sequence[str], minimum: int = 1) -> tuple[int, ...]:
    """Return a sequence of ``len(parts)`` counts as a tuple of ints (each ``>= minimum``).

    ``parts`` names the entries: a wrong length reads "filaments must be (n_axial, n_radial),
    2 positive integers; got (3,)", a bad entry "filaments n_axial must be a positive integer;
    got 0".

    Examples
    --------
    >>> as_counts((3, 2.0), "filaments", ("n_axial", "n_radial"))
    (3, 2)
    """
    what = "positive integers" if minimum == 1 else f"integers >= {minimum}"
    try:
        length = len(value)
    except TypeError:  # a scalar, a 0-d array
        length = None
    if (
        isinstance(value, _TEXT)
        or not isinstance(value, Sequence | np.ndarray)
        or length != len(parts)
    ):
        raise ValueError(
            f"{name} must be ({', '.join(parts)}), {len(parts)} {what}; got {_show(value)}"
        )
    return tuple(
        as_count(v, f"{name} {part}", minimum) for v, part in zip(value, parts, strict=True)
    )


# -- arrays of reals ----------------------------------------------------------------------------
#: Items that numpy would convert to float (or to text) but that are not real numbers.
_NOT_REAL_ITEMS = (*_TEXT, *_FLAGS, complex, np.complexfloating, type(None))


def _has_non_real(seq) -> bool:
    """True if a (nested) list or tuple holds a boolean, a string, a complex number or None."""
    for v in seq:
        if isinstance(v, _NOT_REAL_ITEMS):
            return True
        if isinstance(v, list | tuple) and _has_non_real(v):
            return True
    return False


def _real_array(value, name: str, expected) -> np.ndarray:
    """``value`` as a float ndarray (any shape); ValueError unless it holds real numbers.

    ``expected`` is a callable giving the text "real numbers with shape ..." for the message
    (built only on failure).
    """
    if isinstance(value, np.ndarray):
        kind = value.dtype.kind
        if kind == "f":
            return value.astype(float, copy=False)
        if kind in "iu":
            return value.astype(float)
        raw = value
    elif isinstance(value, list | tuple):
        if not _has_non_real(value):
            try:
                return np.asarray(value, dtype=float)
            except OverflowError:  # integers beyond float
                raise ValueError(f"{name} must be finite; got {_show(value)}") from None
            except (TypeError, ValueError):  # ragged nesting, objects that are not numbers
                pass
        raw = None
    elif isinstance(value, _TEXT + _FLAGS):
        raw = None
    else:  # other array-likes and scalars
        try:
            raw = np.asarray(value)
        except (TypeError, ValueError):
            raw = None
    if raw is not None:
        kind = raw.dtype.kind
        if kind in "iuf":
            return raw.astype(float, copy=False)
        if kind == "O" and all(
            isinstance(v, numbers.Real) and not isinstance(v, _FLAGS) for v in raw.flat
        ):
            try:  # Fraction, integers beyond int64
                return raw.astype(float)
            except OverflowError:
                raise ValueError(f"{name} must be finite; got {_show(value)}") from None
    raise ValueError(f"{name} must be {expected()}; got {_show(value)}")


def _shape_text(shape) -> str:
    inner = ", ".join(str(s) for s in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


def _check_finite(arr: np.ndarray, name: str) -> None:
    if np.isfinite(arr).all():
        return
    if arr.ndim >= 2:
        bad = int(np.argmax(~np.all(np.isfinite(arr.reshape(arr.shape[0], -1)), axis=1)))
        raise ValueError(f"{name} must be finite; row {bad} is {_show(arr[bad].tolist())}")
    raise ValueError(f"{name} must be finite; got {_show(arr.tolist())}")


def as_array(value, name: str, shape: tuple | None = None) -> np.ndarray:
    """Return ``value`` as a finite float ndarray of the given shape.

    Parameters
    ----------
    value : array-like
        Real numbers (see the module docstring).
    name : str
        The argument's name.
    shape : tuple of (int or str), optional
        Required shape; a string entry (``"n"``) allows any length on that axis and names it in
        the message ("filaments must have shape (f, 3); got (2,)").  None: any shape.

    Returns
    -------
    ndarray of float
        A view of ``value`` if it already is a float64 array.
    """
    arr = _real_array(
        value,
        name,
        lambda: (
            "real numbers" if shape is None else f"real numbers with shape {_shape_text(shape)}"
        ),
    )
    if shape is not None and (
        arr.ndim != len(shape)
        or any(isinstance(s, int) and s != n for s, n in zip(shape, arr.shape, strict=True))
    ):
        raise ValueError(f"{name} must have shape {_shape_text(shape)}; got {arr.shape}")
    _check_finite(arr, name)
    return arr


def as_vector(value, name: str, size: int = 3) -> np.ndarray:
    """Return a finite float vector of shape ``(size,)`` ("center must have shape (3,); got
    (2,)", "upper must be finite; got [0.01, inf, 0.01]")."""
    return as_array(value, name, (size,))


def as_points(points, name: str = "points") -> np.ndarray:
    """Return ``points`` as a finite float array of shape (n, 3), m.

    A single point of shape (3,) is promoted to shape (1, 3).  Messages: "points must have
    shape (n, 3); got (3, 2)", "points must be finite; row 1 is [0.0, nan, 0.0]".
    """
    if (
        isinstance(points, np.ndarray)
        and points.dtype == np.float64
        and points.ndim == 2
        and points.shape[1] == 3
    ):
        arr = points  # the solvers' hot path: no conversion
    else:
        arr = _real_array(points, name, lambda: "real numbers with shape (n, 3)")
        if arr.ndim == 1 and arr.shape[0] == 3:
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ValueError(f"{name} must have shape (n, 3); got {arr.shape}")
    _check_finite(arr, name)
    return arr


def as_triple(value, name: str, *, integer: bool = False) -> np.ndarray:
    """A scalar or three values as a float array (3,): positive reals (grid spacings, m), or
    with ``integer`` finite whole numbers (node counts, kept as floats so that an absurd count
    reaches a size limit instead of overflowing; the caller checks their range).

    Messages: "spacing must be a scalar or have shape (3,); got 'abc'", "shape must be
    integers; got [4.0, 4.5, 4.0]", "spacing must be positive; got -1.0".
    """
    bad = f"{name} must be a scalar or have shape (3,); got {_show(value)}"
    try:
        arr = _real_array(value, name, lambda: "a scalar or 3 real numbers")
    except ValueError:
        raise ValueError(bad) from None
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a scalar or have shape (3,); got {np.shape(value)}")
    if integer:
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise ValueError(f"{name} must be integers; got {arr.tolist()}")
        return arr
    return np.array([positive(v, name) for v in arr])


def as_limits(value, name: str, size: int) -> np.ndarray:
    """A positive bound per entry (e.g. current limits, A) as a float array ``(size,)``.

    A scalar applies to every entry; ``inf`` means "no bound"; NaN, zero and negative bounds
    are refused.  Messages: "max_current must be a scalar or have shape (3,); got (2,)",
    "max_current[1] must be positive (inf: no limit); got -2.0".

    Examples
    --------
    >>> as_limits(10, "max_current", 3).tolist()
    [10.0, 10.0, 10.0]
    >>> as_limits([5.0, np.inf], "max_current", 2).tolist()
    [5.0, inf]
    """
    arr = _real_array(value, name, lambda: f"a scalar or real numbers with shape ({size},)")
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ValueError(f"{name} must be a scalar or have shape ({size},); got {arr.shape}")
    for k, v in enumerate(arr):
        if not v > 0:  # NaN, zero, negative
            raise ValueError(f"{name}[{k}] must be positive (inf: no limit); got {v}")
    return arr.copy()


# -- directions ---------------------------------------------------------------------------------
#: A coordinate axis with at most one sign: "y", "-y", "+ Z" (spaces around are allowed).
_AXIS_RE = re.compile(r"\s*([+-]?)\s*([xyz])\s*", re.IGNORECASE)


def as_axis(axis, name: str = "axis") -> np.ndarray:
    """Return a unit vector (3,) from "x", "y", "z" (at most one sign: "-y", "+z") or a
    non-zero finite 3-vector.

    Examples
    --------
    >>> as_axis("-y").tolist()
    [0.0, -1.0, 0.0]
    >>> as_axis("--z")
    Traceback (most recent call last):
    ...
    ValueError: axis must be 'x', 'y' or 'z' with at most one sign ('-y') or a 3-vector; got '--z'
    """
    if isinstance(axis, _TEXT + _FLAGS):
        match = _AXIS_RE.fullmatch(axis) if isinstance(axis, str) else None
        if match is None:
            raise ValueError(
                f"{name} must be 'x', 'y' or 'z' with at most one sign ('-y') or a 3-vector; "
                f"got {_show(axis)}"
            )
        vec = np.zeros(3)
        vec["xyz".index(match[2].lower())] = -1.0 if match[1] == "-" else 1.0
        return vec
    vec = as_vector(axis, name)
    largest = float(np.abs(vec).max())
    if largest == 0:
        raise ValueError(f"{name} must be a non-zero vector; got {vec.tolist()}")
    vec = vec / largest  # no overflow or underflow in the norm
    return vec / np.linalg.norm(vec)


# -- flags, options, objects --------------------------------------------------------------------
def as_bool(value, name: str) -> bool:
    """Return a ``bool`` (or ``numpy.bool_``) as bool; anything else, ``"no"`` or ``0``
    included, raises "NAME must be True or False; got 'no'"."""
    if isinstance(value, _FLAGS):
        return bool(value)
    raise ValueError(f"{name} must be True or False; got {_show(value)}")


def as_choice(value, name: str, choices: Sequence[str]) -> str:
    """Return ``value`` if it is one of the strings ``choices``.

    Message: "outside must be 'raise' or 'direct'; got 'clip'" (up to three choices) or
    "plane must be one of 'xy', 'xz', ...; got 'ab'".
    """
    if isinstance(value, str) and value in choices:
        return str(value)
    quoted = [repr(c) for c in choices]
    if len(quoted) <= 3:
        alternatives = (
            quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + f" or {quoted[-1]}"
        )
    else:
        alternatives = "one of " + ", ".join(quoted)
    raise ValueError(f"{name} must be {alternatives}; got {_show(value)}")
