"""Design studies: how far real coils move the robot from the ideal-field prediction.

The figure a coil designer needs is the tip shift against coil size (radius / robot length) and
against where the robot sits in the coils.  Each point of a study is two rod solves with the same
load path: in the coil's Biot-Savart field and in its ideal linearisation at the coil centre.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import coils

from ..robot.rod import Rod

__all__ = ["coil_shift", "shift_vs_radius", "shift_vs_placement", "plot_shift", "make_pair"]


def make_pair(
    kind: str, radius: float, target: float, *, turns: float = 200, axis="y", center=(0.0, 0.0, 0.0)
) -> coils.CoilPair:
    """A Helmholtz pair with centre field ``target`` (T) or a Maxwell pair with centre gradient
    ``target`` (T/m), of the given radius (m), with the current that meets the target."""
    from coils.design import current_for_field, current_for_gradient

    if kind == "helmholtz":
        unit = coils.HelmholtzPair(radius, turns, 1.0, axis=axis, center=center)
        return coils.HelmholtzPair(
            radius, turns, current_for_field(unit, target), axis=axis, center=center
        )
    if kind == "maxwell":
        unit = coils.MaxwellPair(radius, turns, 1.0, axis=axis, center=center)
        return coils.MaxwellPair(
            radius, turns, current_for_gradient(unit, target), axis=axis, center=center
        )
    raise ValueError(f"kind must be 'helmholtz' or 'maxwell'; got {kind!r}")


def coil_shift(
    rod: Rod, field: coils.Field, scales=None, *, ideal: coils.Field | None = None, **solve_options
) -> dict:
    """Solve ``rod`` in ``field`` and in its ideal counterpart; report the tip shift.

    Parameters
    ----------
    rod : Rod
    field : coils.Field
        The real field (a coil, pair or system with ``ideal()``).
    scales : array-like, optional
        Load path (default 10 equal steps to 1).
    ideal : coils.Field, optional
        The reference field (default ``field.ideal()``).
    **solve_options
        Passed to :func:`coilrod.solve_rod`.

    Returns
    -------
    dict
        ``tip_real``, ``tip_ideal`` (m, shape (3,)), ``tip_shift`` (m), ``tip_shift_over_L``,
        ``angle_shift`` (rad, real minus ideal), at the last scale.
    """
    from ..rod import solve_rod

    scales = np.linspace(0.1, 1.0, 10) if scales is None else np.asarray(scales, dtype=float)
    ideal = field.ideal() if ideal is None else ideal
    real = solve_rod(rod, field, scales, **solve_options)
    ref = solve_rod(rod, ideal, scales, **solve_options)
    shift = float(np.linalg.norm(real.tip[-1] - ref.tip[-1]))
    return {
        "tip_real": real.tip[-1],
        "tip_ideal": ref.tip[-1],
        "tip_shift": shift,
        "tip_shift_over_L": shift / rod.length,
        "angle_shift": float(real.tip_angle[-1] - ref.tip_angle[-1]),
    }


def shift_vs_radius(
    rod: Rod,
    kind: str,
    radius_over_length: Sequence[float],
    target: float,
    *,
    scales=None,
    axis="y",
    placement=(0.0, 0.0, 0.0),
    turns: float = 200,
    bias: coils.Field | None = None,
    progress: bool = False,
    **solve_options,
) -> list[dict]:
    """Tip shift (real coils vs ideal) against coil radius / robot length.

    Parameters
    ----------
    rod : Rod
        The robot, clamped at the origin along +x.
    kind : {"helmholtz", "maxwell"}
    radius_over_length : sequence of float
        Coil radii as multiples of the rod length.
    target : float
        Centre field (T, Helmholtz) or centre gradient (T/m, Maxwell), held fixed as the radius
        changes, so every point has the same ideal prediction.
    placement : array-like, shape (3,)
        Coil centre relative to the clamp, m.
    bias : coils.Field, optional
        An extra field added to both real and ideal fields (e.g. a uniform bias for Config (B)).

    Returns
    -------
    list of dict
        Per radius: ``radius_over_length``, ``radius`` (m) and the entries of
        :func:`coil_shift`.
    """
    rows = []
    values = list(radius_over_length)
    iterator = values
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(values, desc=f"{kind} radius sweep")
    for ratio in iterator:
        pair = make_pair(kind, ratio * rod.length, target, turns=turns, axis=axis, center=placement)
        real, ideal = pair, pair.ideal()
        if bias is not None:
            real, ideal = real + bias, ideal + bias
        row = coil_shift(rod, real, scales, ideal=ideal, **solve_options)
        row.update(radius_over_length=float(ratio), radius=float(ratio * rod.length))
        rows.append(row)
    return rows


def shift_vs_placement(
    rod: Rod, field_at: callable, offsets, *, scales=None, progress: bool = False, **solve_options
) -> list[dict]:
    """Tip shift against the coil centre's position relative to the robot's clamp.

    Parameters
    ----------
    field_at : callable
        ``field_at(center) -> coils.Field``: the coil arrangement centred at ``center`` (m).
    offsets : array-like, shape (k, 3)
        Coil centres relative to the clamp, m.  The ideal field is always the linearisation
        at the coil centre -- what a model that ignores placement would use.
    """
    offsets = np.asarray(offsets, dtype=float).reshape(-1, 3)
    rows = []
    iterator = offsets
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(offsets, desc="placement sweep")
    for c in iterator:
        real = field_at(c)
        row = coil_shift(rod, real, scales, **solve_options)
        row.update(offset=c.copy())
        rows.append(row)
    return rows


def plot_shift(
    rows: list[dict], x: str = "radius_over_length", ax=None, label: str = "", percent: bool = True
):
    """Plot the tip shift (percent of L, or metres) of a study against ``x``."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    xs = [r[x] if np.ndim(r[x]) == 0 else r[x][0] for r in rows]
    ys = [100 * r["tip_shift_over_L"] if percent else r["tip_shift"] for r in rows]
    ax.loglog(xs, ys, "o-", label=label or None)
    ax.set_xlabel({"radius_over_length": "coil radius / robot length R/L"}.get(x, x))
    ax.set_ylabel("tip shift, real vs ideal (% of L)" if percent else "tip shift (m)")
    ax.grid(alpha=0.3, which="both")
    if label:
        ax.legend(fontsize=8)
    return ax
