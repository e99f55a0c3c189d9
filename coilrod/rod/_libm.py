"""C libm's sin and cos, elementwise, for the numpy passes that must match compiled kernels.

numba's kernels call C's libm; numpy's own ``np.sin``/``np.cos`` may differ from it in the
last bit on some CPUs, and a numpy pass must give the compiled kernel's numbers bitwise.
Python's :mod:`math` calls libm too, but raises on an infinite argument where libm returns
NaN: :func:`libm` returns NaN there, as the kernel does.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np


def libm(f: Callable[[float], float], x: np.ndarray) -> np.ndarray:
    """``f`` (a :mod:`math` function) of every element of ``x`` (any shape; same shape out);
    NaN where ``x`` is infinite (where :mod:`math` raises and C's libm returns NaN)."""
    values = x.ravel().tolist()
    try:
        out = [f(v) for v in values]
    except ValueError:  # sin or cos of +-inf
        out = [f(v) if math.isfinite(v) else math.nan for v in values]
    return np.array(out).reshape(x.shape)
