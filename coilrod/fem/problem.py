"""The finite-element model as a :class:`~coilrod.path.PathProblem` for the shared engine.

State ``z = [free displacement dofs, element pressure coefficients]`` (see
:class:`~coilrod.fem.assembly.Assembler`).  The residual handed to the engine is
``[r_hat; r_p]``: the condensed displacement residual ``r_hat = R_u + K B^T M^-1 R_p`` and the
element pressure equations ``R_p = int phi (J - 1) - M a / K``.  That is ``T R`` with an
invertible ``T``, so it vanishes with ``R`` and the engine's solves ``(T J)^-1 c`` are, by
static condensation, ``du = K_hat^-1 c_u`` and ``da = K M^-1 (B du - c_p)`` -- the tangent
``K_hat = K_uu + K B^T M^-1 B`` is factorised once per state and serves the Newton step, the
path tangent and the stability check.

Convergence (:meth:`FEMProblem.error` <= 1): the residual norm is below
``rtol * max(|internal force|, |scale| |magnetic load|)`` plus a round-off floor
``~ eps K V / L``, the element pressure equations hold to ``100 rtol G / K``, and the last
Newton increment is below ``utol L`` (or the residual is at the floor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..path.protocol import Linearization, PathProblem
from . import linalg

__all__ = ["FEMProblem", "SolveStats"]


@dataclass
class SolveStats:
    """Counters of one solve: Newton iterations, evaluations, factorisations, load steps."""

    iterations: list = field(default_factory=list)  # Newton iterations per requested scale
    evaluations: int = 0
    factorizations: int = 0
    cuts: int = 0
    steps: int = 0


class _Tangent:
    """An evaluation whose tangent is (or will be, on first use) factorised; ``u`` and
    ``scale`` locate it (a chord iteration pairs a newer state with an older tangent)."""

    def __init__(self, ev, u, scale):
        self.ev = ev
        self.u = u
        self.scale = float(scale)
        self.factor = None


class FEMProblem(PathProblem):
    """Equilibrium of the discretised body in the field times the load scale.

    Parameters
    ----------
    asm : Assembler
    rtol, utol : float
        Residual tolerance relative to the force scale; increment tolerance relative to L.
    """

    batched = False
    #: Largest correction (max nodal displacement change / L) between the predicted and the
    #: converged state of a load step.
    max_correction = 0.25
    #: Largest predicted change (max nodal displacement / L) in one load step.  0.15 split
    #: the early steps of a cantilever curve (lambda 0.5 ... 10 by 0.5: 30 sub-steps instead
    #: of the 20 requested ones, each converging no faster); 0.3 let a 2D plane-stress curve
    #: take steps that needed more iterations than they saved (42 against 28 at 0.2).
    max_step_change = 0.2
    #: Chord (modified Newton) steps only once an iteration has cut the error a thousandfold:
    #: the nearly incompressible tangent (K/G ~ 1000) changes too much over a Newton step for
    #: the old factorisation to contract the error at the engine's default 1/8 (the chord step
    #: then raised the error and cost an iteration).
    chord = 1e-3
    #: A full Newton step may raise the residual this much (large rotations).
    full_step_growth = 1e4

    def __init__(self, asm, rtol: float, utol: float):
        self.asm = asm
        self.size = asm.size
        self.rtol, self.utol = float(rtol), float(utol)
        self.L = asm.length
        # absolute force floor: round-off of the volumetric terms, ~ eps K (volume / length)
        self.atol = 1e4 * np.finfo(float).eps * max(asm.bulk, asm.shear) * asm.w.sum() / self.L
        self.ctol = 100 * self.rtol * asm.shear / asm.bulk
        self.stats = SolveStats()
        self.last_failure = ""
        self._reference = None

    # -- evaluation ---------------------------------------------------------------------------
    def linearize(self, z, scale, tangent: bool = True) -> Linearization:
        asm = self.asm
        self.stats.evaluations += 1
        try:
            with np.errstate(all="ignore"):
                ev = asm.evaluate(z, float(scale), tangent=tangent)
        except ValueError as exc:  # the field refuses a point (a coil winding)
            self.last_failure = (
                f"the field could not be evaluated on the deformed body ({exc}): the body "
                "reaches a point where the field source refuses to answer (a coil winding, or "
                "outside a gridded field's bounds)"
            )
            return Linearization(z, scale, np.full(self.size, np.nan), False)
        if not ev.ok:
            self.last_failure = (
                "the deformed body is inadmissible at the trial states (an element inverted, "
                f"min det F = {ev.min_jacobian:.3g}, or a non-finite field)"
            )
            return Linearization(z, scale, np.full(self.size, np.nan), False)
        parts = [ev.residual]
        if asm.mixed:
            parts.append(ev.constraint_residual.ravel())
        residual = np.concatenate(parts) if len(parts) > 1 else ev.residual
        ok = bool(np.all(np.isfinite(residual)))
        lin = Linearization(z, scale, residual, ok, _Tangent(ev, z, scale))
        lin.ev = ev  # this state's evaluation (the tangent may come from an earlier one)
        return lin

    def _factor(self, lin: Linearization):
        tan = lin.tangent
        if tan.factor is None:
            if tan.ev.tangent is None:  # evaluated without tangent: evaluate again with it
                tan.ev = self.asm.evaluate(tan.u, tan.scale, tangent=True)
                self.stats.evaluations += 1
            tan.factor = self.asm.factorize(tan.ev)
            self.stats.factorizations += 1
        return tan.factor

    def solve(self, lin: Linearization, rhs: np.ndarray) -> np.ndarray:
        """``(T J)^-1 rhs`` by static condensation (module docstring)."""
        factor = self._factor(lin)
        asm = self.asm
        rhs = np.asarray(rhs, float)
        du = factor.solve(rhs[: asm.nfree])
        if not np.all(np.isfinite(du)):
            raise np.linalg.LinAlgError("singular FEM tangent")
        if not asm.mixed:
            return du
        cp = rhs[asm.nfree :].reshape(asm.nel, -1)
        return asm._recover(lin.tangent.ev, du, -cp)

    def d_residual_d_scale(self, lin: Linearization) -> np.ndarray:
        out = np.zeros(self.size)
        out[: self.asm.nfree] = lin.ev.load_rate
        return out

    def error(self, lin: Linearization, du) -> float:
        """Convergence measure (<= 1 converged; see the module docstring)."""
        if not lin.ok:
            return math.inf
        ev = lin.ev
        rnorm = float(np.linalg.norm(ev.residual))
        fref = max(ev.internal_norm, abs(float(lin.scale)) * float(np.linalg.norm(ev.load_rate)))
        e_res = rnorm / (self.rtol * fref + self.atol)
        e_con = ev.constraint_norm / self.ctol if self.asm.mixed else 0.0
        at_floor = rnorm / self.atol
        if du is None:
            return max(e_res, e_con, at_floor)
        step = self.asm.increment_norm(np.asarray(du, float))
        err = max(e_res, e_con, min(step / (self.utol * self.L), at_floor))
        # round-off floor: an increment at round-off level with a residual near tolerance
        if step <= 1e-3 * self.utol * self.L and rnorm <= 100 * self.rtol * fref:
            err = min(err, 1.0)
        return err

    def distance(self, du) -> float:
        """Largest nodal displacement change over L."""
        return self.asm.increment_norm(np.asarray(du, float)) / self.L

    def arclength_weights(self) -> np.ndarray:
        w = np.zeros(self.size)
        w[: self.asm.nfree] = 1.0 / (self.asm.nfree * self.L**2)
        return w

    # -- stability ----------------------------------------------------------------------------
    def _inertia(self, lin: Linearization) -> tuple[int | None, int]:
        factor = self._factor(lin)
        count = None
        counter = getattr(linalg, "negative_eigenvalues", None)
        if counter is not None:
            count = counter(factor)
        return count, linalg.determinant_sign(factor)

    def stability(self, lin: Linearization, precise: bool = False) -> float:
        """+1 if the condensed tangent has as many negative eigenvalues as the unloaded body
        (none), -1 otherwise: counted where the factorisation reveals the inertia, else from
        the sign of the determinant (an odd number of eigenvalues crossed zero)."""
        count, sign = self._inertia(lin)
        if self._reference is None:
            self._reference = (count, sign)
        ref_count, ref_sign = self._reference
        if count is not None and ref_count is not None:
            return 1.0 if count == ref_count else -1.0
        return 1.0 if sign == ref_sign else -1.0
