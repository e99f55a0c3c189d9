"""Magnetization design: the segment layout that maximises the workspace area.

The rod is cut into ``segments`` equal segments, each with its own magnitude
(0 ... ``max_magnitude``) and direction (free).  The objective is the workspace area
(:func:`coilrod.workspace`, refined up to the antiparallel cut, directions measured from the
rod's net moment) at a field bound ``b_max``.  The result reports the ratio to the axial
uniform magnetization (``max_magnitude``), the baseline a layout must beat (a tilted uniform
one has the same equilibria, turned, but its own 3D stability).  That baseline is a layout of
the search space (every segment at ``max_magnitude``, angle 0): it is evaluated first, as a
candidate like any other, and the result is the best layout evaluated, so ``ratio >= 1``.

* ``method="gradient"``: L-BFGS-B from several starts, with the exact gradient: the area's
  derivative with respect to the tips (:func:`coilrod.design.workspace.area_gradient`) times
  the tips' total derivative: their adjoint sensitivities (:func:`coilrod.sensitivities`, all
  states of all directions at once) plus the turn of the workspace's directions with the
  rod's net moment (:func:`coilrod.design.workspace.reference_direction`; turning every
  segment by delta is turning the field by -delta, so d tip/d phi = -sum of d tip/d angle).
  The area is a smooth function of the layout as long as the refined grid and the set of
  included cells do not change; where they do (a bisection added or dropped, a snap-through
  appearing), the area jumps by about its ``area_error``.  The gradient then describes the
  current grid only, the line search of L-BFGS-B backs off from the jump, and the several
  starts guard against being stuck at one.
* ``method="evolution"``: :func:`scipy.optimize.differential_evolution` (derivative-free, the
  kind of method behind the seed's cited M(4.1) design).

``solves`` counts workspace evaluations, the baseline's included (each = one forward solve of
every direction's load path; the gradient method's sensitivities are not counted as solves:
they cost a fraction of a solve, one transposed factorised solve per output and state).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from coils._validate import as_count, positive

from ..robot.magnetization import Magnetization
from ..robot.rod import Rod
from .workspace import Workspace, area_gradient, tip_derivatives, workspace

__all__ = ["optimize_magnetization", "MagnetizationDesign"]


@dataclass
class MagnetizationDesign:
    """Result of :func:`optimize_magnetization`.

    Attributes
    ----------
    magnetization : Magnetization
        The best segment layout found.
    area : float
        Its workspace area, m^2 (at the optimisation's resolution).
    solves : int
        Workspace evaluations used.
    history : ndarray, shape (solves, 2)
        (evaluation number, best area so far in m^2) after each evaluation.
    method : str
    magnitudes : ndarray, shape (segments,)
        A/m.
    angles : ndarray, shape (segments,)
        rad, wrapped to (-pi, pi].
    workspace : Workspace
        The best layout's workspace.
    seconds : float
        CPU time spent, s.
    uniform_area : float
        The workspace area of the axial uniform magnetization, m^2: |M| = ``max_magnitude``
        along the rod (a layout of the search space, evaluated first as a candidate).  A
        uniform magnetization at another angle has the same planar equilibria (turning it is
        turning the field), but not the same 3D stability (a twist turns its normal component
        out of the plane), so its area may differ.
    ratio : float
        ``area / uniform_area`` (>= 1: the baseline is a candidate): what the segment layout
        gains over a uniform magnetization.
    """

    magnetization: Magnetization
    area: float
    solves: int
    history: np.ndarray
    method: str
    magnitudes: np.ndarray
    angles: np.ndarray
    workspace: Workspace
    seconds: float
    uniform_area: float = float("nan")

    @property
    def ratio(self) -> float:
        return self.area / self.uniform_area


class _Objective:
    """Workspace area of a layout x = (magnitudes / max, angles), with a record of every
    evaluation."""

    def __init__(
        self, rod, segments, b_max, max_magnitude, directions, magnitudes, refine, tolerance, budget
    ):
        self.rod, self.segments = rod, segments
        self.lengths = np.full(segments, rod.length / segments)
        self.b_max, self.max_mag = b_max, max_magnitude
        self.kw = dict(
            directions=directions, magnitudes=magnitudes, refine=refine, tolerance=tolerance
        )
        self.budget = budget
        self.solves = 0
        self.best = (-np.inf, None, None)
        self.history = []
        self._cache = {}
        self.start_limit = np.inf

    def layout(self, x):
        x = np.asarray(x, float)
        mags = np.clip(x[: self.segments], 0.0, 1.0) * self.max_mag
        angles = np.angle(np.exp(1j * x[self.segments :]))
        return mags, angles

    def rod_for(self, x) -> Rod:
        mags, angles = self.layout(x)
        m = Magnetization.segments(self.lengths, mags, angles, label="optimised")
        return dataclasses.replace(self.rod, magnetization=m)

    def reference_rate(self, x) -> np.ndarray:
        """d(reference direction)/d(magnitudes [A/m], angles [rad]) of layout x, (2 S,):
        the net moment is sum_s l_s M_s (cos a_s, sin a_s)."""
        mags, angles = self.layout(x)
        e = np.stack([np.cos(angles), np.sin(angles)], 1)
        N = (self.lengths * mags) @ e
        n2 = N @ N
        if n2 <= 1e-18 * (self.lengths @ mags) ** 2:
            return np.zeros(2 * self.segments)
        dN = np.concatenate(
            [self.lengths[:, None] * e, (self.lengths * mags)[:, None] * e[:, ::-1] * [-1, 1]]
        )
        return (N[0] * dN[:, 1] - N[1] * dN[:, 0]) / n2

    def evaluate(self, x, gradient: bool):
        key = tuple(np.round(np.asarray(x, float), 15))
        if key in self._cache and (not gradient or self._cache[key][1] is not None):
            return self._cache[key]
        if self.solves >= self.budget:
            raise _BudgetSpent
        if self.solves >= self.start_limit:
            raise _StartSpent
        rod = self.rod_for(x)
        ws = workspace(rod, self.b_max, **self.kw)
        self.solves += 1
        grad = None
        if gradient:
            g_tip = area_gradient(ws)  # (D, M + 1, 2)
            _, dT = tip_derivatives(ws, ["magnitudes", "angles"])  # (D, M + 1, 2, p)
            # the directions turn with the reference (the net moment's direction psi): the
            # tips at psi + alpha move by dT/dphi dpsi/dp, and turning every segment by delta
            # is the field turned by -delta, so dT/dphi = -sum of dT/d(angle)
            dT_dphi = -dT[..., self.segments :].sum(axis=-1)
            dT = dT + dT_dphi[..., None] * self.reference_rate(x)[None, None, None, :]
            grad = np.einsum("dmc,dmcp->p", g_tip, dT)
            grad[: self.segments] *= self.max_mag  # per unit of x
        if ws.area > self.best[0]:
            self.best = (ws.area, np.asarray(x, float).copy(), ws)
        self.history.append((self.solves, self.best[0]))
        self._cache[key] = (ws.area, grad)
        return ws.area, grad


class _BudgetSpent(Exception):
    pass


class _StartSpent(Exception):
    pass


def _gradient_search(obj: _Objective, starts: int, rng) -> None:
    """L-BFGS-B on the area with its exact gradient from ``starts`` starts, each with its share
    of the budget (the layouts met are kept by ``obj``)."""
    from scipy.optimize import minimize

    rod, segments, budget = obj.rod, obj.segments, obj.budget
    # first start: M(2a) in segments (direction turning by pi/2 along the rod, full
    # magnitude), a good design of the seed; then random ones.  No layout with exactly
    # aligned segments (e.g. all axial): it puts an exact pitchfork in the antiparallel
    # direction, where the area is not smooth
    turning = np.pi / 2 * (np.arange(segments) + 0.5) / segments
    x0s = [np.r_[np.ones(segments), turning]]
    x0s += [
        np.r_[rng.uniform(0.5, 1.0, segments), rng.uniform(-np.pi, np.pi, segments)]
        for _ in range(starts - 1)
    ]
    bounds = [(0.0, 1.0)] * segments + [(-2 * np.pi, 2 * np.pi)] * segments

    def fun(x):
        area, grad = obj.evaluate(x, True)
        return -area / rod.length**2, -grad / rod.length**2

    for i, x0 in enumerate(x0s):
        if obj.solves >= budget:
            break
        # each start gets its share of the budget (a start stuck at a local optimum
        # whose line searches keep failing on the area's jumps hands over in time)
        share = (budget - obj.solves) // (len(x0s) - i)
        obj.start_limit = obj.solves + max(share, 1)
        try:
            minimize(
                fun,
                x0,
                jac=True,
                method="L-BFGS-B",
                bounds=bounds,
                options={"maxfun": max(share, 1), "ftol": 1e-6, "gtol": 1e-8},
            )
        except _StartSpent:
            pass
    obj.start_limit = np.inf


def _evolution_search(obj: _Objective, seed, x0) -> None:
    """Differential evolution on the area within the budget (the layouts met are kept by
    ``obj``)."""
    from scipy.optimize import differential_evolution

    rod, segments, budget = obj.rod, obj.segments, obj.budget
    n = 2 * segments
    bounds = [(0.0, 1.0)] * segments + [(-np.pi, np.pi)] * segments
    popsize = 10
    maxiter = max(1, budget // (popsize * n) - 1)
    differential_evolution(
        lambda x: -obj.evaluate(x, False)[0] / rod.length**2,
        bounds,
        seed=seed,
        popsize=popsize,
        maxiter=maxiter,
        polish=False,
        tol=1e-8,
        x0=x0,  # the baseline in the first population (already evaluated: no extra solve)
    )


def optimize_magnetization(
    rod: Rod,
    segments: int = 4,
    b_max: float = 0.02,
    method: str = "gradient",
    max_magnitude: float | None = None,
    budget: int | None = None,
    seed: int = 0,
    *,
    directions: int = 36,
    magnitudes: int = 8,
    refine: int = 6,
    tolerance: float = 1e-3,
    starts: int = 4,
) -> MagnetizationDesign:
    """Segment magnitudes and directions that maximise the workspace area at ``b_max``.

    Parameters
    ----------
    rod : Rod
        Geometry and modulus (its own magnetization is replaced; it must be planar, as the
        designs and their workspaces are: an out-of-plane elevation is a ValueError).
    segments : int
        Equal segments from the clamp to the tip (>= 1).
    b_max : float
        Field bound, T (> 0).
    method : {"gradient", "evolution"}
    max_magnitude : float, optional
        Upper bound of each segment's |M|, A/m (> 0); default: the rod's largest |M|.
    budget : int, optional
        Most workspace evaluations (default 400 for "gradient", 4000 for "evolution"), the
        first being the baseline's (the axial uniform magnetization at ``max_magnitude``,
        a candidate: the result is never worse than it).
    seed : int
        Random seed (the starts of "gradient", the population of "evolution").
    directions, magnitudes, refine, tolerance
        Initial grid and refinement of the workspaces evaluated (see :func:`coilrod.workspace`).
    starts : int
        Starts of the gradient method: M(2a) in segments (the direction turning by pi/2
        from clamp to tip, magnitudes at the bound), then random layouts (magnitudes 0.5 to 1
        of the bound, any angles).

    Returns
    -------
    MagnetizationDesign

    Examples
    --------
    >>> from coilrod import presets, optimize_magnetization
    >>> rod = presets.seed_rod(presets.M1())
    >>> best = optimize_magnetization(rod, segments=1, b_max=0.01, budget=6, starts=1,
    ...                               directions=8, magnitudes=3, refine=1)
    >>> best.solves <= 6 and best.area > 0
    True
    """
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    rod.magnetization.check_planar("optimize_magnetization (planar workspaces)")
    segments = as_count(segments, "segments", 1, 64)
    b_max = positive(b_max, "b_max")
    if method not in ("gradient", "evolution"):
        raise ValueError(f"method must be 'gradient' or 'evolution'; got {method!r}")
    if max_magnitude is None:
        max_magnitude = rod.magnetization.max_magnitude(rod.length)
    max_magnitude = positive(max_magnitude, "max_magnitude")
    default = 400 if method == "gradient" else 4000
    budget = as_count(default if budget is None else budget, "budget", 1, 10**6)
    starts = as_count(starts, "starts", 1, 1000)
    obj = _Objective(
        rod, segments, b_max, max_magnitude, directions, magnitudes, refine, tolerance, budget
    )
    rng = np.random.default_rng(seed)
    t0 = time.process_time()
    # the baseline, the axial uniform magnetization at the bound, is the layout with every
    # segment at max_magnitude and angle 0: evaluated first (budget >= 1) as a candidate, so
    # the design returned (the best layout evaluated) is never worse than it.  It is not a
    # gradient start: its aligned segments put an exact pitchfork in the antiparallel
    # direction, where the area is not smooth
    x_uniform = np.r_[np.ones(segments), np.zeros(segments)]
    uniform_area = obj.evaluate(x_uniform, False)[0]
    try:
        if method == "gradient":
            _gradient_search(obj, starts, rng)
        else:
            _evolution_search(obj, seed, x_uniform)
    except _BudgetSpent:
        pass
    area, x, ws = obj.best
    mags, angles = obj.layout(x)
    return MagnetizationDesign(
        magnetization=ws._solution.rod.magnetization,
        area=float(area),
        solves=obj.solves,
        history=np.array(obj.history, float),
        method=method,
        magnitudes=mags,
        angles=angles,
        workspace=ws,
        seconds=time.process_time() - t0,
        uniform_area=float(uniform_area),
    )
