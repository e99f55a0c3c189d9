"""Validation of counts (sample, node and cell numbers): integers, not booleans, above a floor.

Kept beside :mod:`coils._validate` (whose helpers check real numbers and vectors) so the modules
that take counts -- the grid cache, uniformity reports, field maps -- share one message.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["as_count"]


def as_count(value, name: str, minimum: int = 1) -> int:
    """Return ``value`` as an int ``>= minimum``.

    Integral floats (``4.0``) are accepted; booleans, fractions, NaN, infinities and strings are
    not.  The message names the parameter: "samples must be an integer >= 2; got 1".
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {what}; got {value!r}")
    if isinstance(value, numbers.Integral):
        count = int(value)
    else:
        as_float = float(value)
        if not math.isfinite(as_float) or not as_float.is_integer():
            raise ValueError(f"{name} must be {what}; got {value!r}")
        count = int(as_float)
    if count < minimum:
        raise ValueError(f"{name} must be {what}; got {value!r}")
    return count
