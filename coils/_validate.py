"""One place for input validation (errors are ``ValueError`` subclasses with a clear message)."""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["as_points", "as_vector", "positive", "finite_scalar", "as_axis"]


def as_points(points, name: str = "points") -> np.ndarray:
    """Return ``points`` as a float array of shape (n, 3), checking shape and finiteness.

    A single point of shape (3,) is accepted and promoted to shape (1, 3).
    """
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3); got {np.shape(points)}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.argmax(~np.all(np.isfinite(arr), axis=1)))
        raise ValueError(f"{name} must be finite; row {bad} is {arr[bad].tolist()}")
    return arr


def as_vector(value, name: str, size: int = 3) -> np.ndarray:
    """Return a finite float vector of length ``size``."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},); got {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    return arr


def finite_scalar(value, name: str) -> float:
    """Return ``value`` as a finite float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real | np.ndarray):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a real number; got {value!r}") from None
    arr = np.asarray(value, dtype=float)
    if arr.shape != ():
        raise ValueError(f"{name} must be a scalar; got shape {arr.shape}")
    val = float(arr)
    if not np.isfinite(val):
        raise ValueError(f"{name} must be finite; got {val}")
    return val


def positive(value, name: str) -> float:
    """Return ``value`` as a finite float > 0."""
    val = finite_scalar(value, name)
    if val <= 0:
        raise ValueError(f"{name} must be positive; got {val}")
    return val


_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def as_axis(axis, name: str = "axis") -> np.ndarray:
    """Return a unit vector from "x", "y", "z" (optionally signed, e.g. "-y") or a 3-vector."""
    if isinstance(axis, str):
        key = axis.strip().lower()
        sign = -1.0 if key.startswith("-") else 1.0
        key = key.lstrip("+-")
        if key not in _AXES:
            raise ValueError(f"{name} must be 'x', 'y', 'z' or a 3-vector; got {axis!r}")
        return sign * np.array(_AXES[key])
    vec = as_vector(axis, name)
    norm = np.linalg.norm(vec)
    if norm == 0:
        raise ValueError(f"{name} must be a non-zero vector")
    return vec / norm
