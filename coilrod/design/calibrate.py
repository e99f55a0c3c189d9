"""Calibration from data: the rod's modulus, magnetization or field misalignment fitted to
measured tip outputs by least squares with the exact (adjoint) Jacobian.

The model is the planar rod of :func:`coilrod.solve_rod` in uniform fields.  Each applied
field is one state; fields along one direction form one load path (one ``solve_rod`` call)
and all its states' derivatives come from one batched adjoint
(:func:`coilrod.design.sensitivity.tip_derivatives`).  :func:`scipy.optimize.least_squares`
is driven with that Jacobian, so a fit costs one path solve per direction per iteration.

Identifiability
---------------
Without gravity the rod's equilibrium in a uniform field depends on E and |M| only through
the magneto-elastic number ``lambda = A |M| |B| L^2 / (E I)``: the load is linear in |M| and
the stiffness in E (any field: the gradient number ``gamma`` has the same ratio).  So
deflection-against-field data determine |M| / E and nothing else; the Jacobian columns obey
``dtip/dE = -(|M| / E) dtip/d|M|`` exactly.  :func:`calibrate` checks the rank of the
Jacobian before and after the fit and raises :class:`IdentifiabilityError` rather than
return an arbitrary point of the ridge: fix one of the two (|M| = Br / mu0 from a measured
remanence Br, or E from a tensile test).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.constants import mu_0

import coils
from coils._validate import as_array, as_choice, as_count, finite_scalar, positive

from ..errors import ConvergenceError
from ..robot.magnetization import Magnetization
from ..robot.rod import Rod
from ..rod.so3 import about_z
from ..rod.solve import solve_rod
from .sensitivity import SingularStateError, tip_derivatives

__all__ = [
    "calibrate",
    "Calibration",
    "IdentifiabilityError",
    "UnstableStateError",
    "PARAMETERS",
    "OUTPUTS",
]

#: Parameters :func:`calibrate` can fit: name -> (unit, fitted in log).
PARAMETERS = {
    "youngs_modulus": ("Pa", True),
    "magnitude": ("A/m", True),
    "field_angle": ("rad", False),
}
#: Outputs that can be measured: name -> (unit, row of the tip Jacobian (x, y, z, angle)).
OUTPUTS = {"tip_x": ("m", 0), "tip_y": ("m", 1), "tip_angle": ("rad", 3)}
#: Options of :func:`coilrod.solve_rod` a calibration may set.
SOLVE_OPTIONS = ("nodes", "richardson", "tol", "max_iter", "clamp_position", "clamp_angle")
#: Fields whose unit vectors differ by less than this form one load path.
_SAME_DIRECTION = 1e-12


class IdentifiabilityError(ValueError):
    """The data cannot determine the fitted parameters separately (rank-deficient Jacobian)."""


class UnstableStateError(ValueError):
    """A model state at a data point is unstable (a branch no experiment can stay on)."""


@dataclass(frozen=True)
class _Group:
    """Fields along one direction: one load path."""

    direction: np.ndarray  # (3,) unit vector (before the misalignment rotation)
    rows: np.ndarray  # (g,) indices into the data
    magnitudes: np.ndarray  # (g,) |B| in T


def _direction_groups(fields: np.ndarray) -> list[_Group]:
    """Split fields (k, 3) into load paths along common directions; zero fields join the first
    path at scale 0 (the straight rod)."""
    norms = np.linalg.norm(fields, axis=1)
    nonzero = np.flatnonzero(norms > 0)
    if nonzero.size == 0:
        raise ValueError("fields are all zero: the straight rod does not depend on the parameters")
    units = fields[nonzero] / norms[nonzero, None]
    groups, taken = [], np.zeros(nonzero.size, bool)
    for i in range(nonzero.size):
        if taken[i]:
            continue
        same = ~taken & (np.linalg.norm(units - units[i], axis=1) < _SAME_DIRECTION)
        taken |= same
        rows = nonzero[same]
        groups.append(_Group(units[i].copy(), rows, norms[rows]))
    zero = np.flatnonzero(norms == 0)
    if zero.size:
        g = groups[0]
        groups[0] = _Group(
            g.direction, np.concatenate([zero, g.rows]), np.concatenate([0 * zero, g.magnitudes])
        )
    return groups


class _Model:
    """Model outputs and their derivatives at fit variables x (log E, log |M|, angle)."""

    def __init__(self, rod, fields, output, fit, field_angle, solve_options):
        self.rod, self.fit, self.field_angle = rod, fit, field_angle
        self.row = OUTPUTS[output][1]
        self.groups = _direction_groups(fields)
        self.k = fields.shape[0]
        self.options = solve_options
        self.solves = 0
        self._cache: dict = {}

    # -- parameters -----------------------------------------------------------------------------
    def initial(self) -> dict:
        out = {"youngs_modulus": self.rod.youngs_modulus, "field_angle": self.field_angle}
        if "magnitude" in self.fit:
            out["magnitude"] = float(self.rod.magnetization.magnitude(np.zeros(1))[0])
        return {name: out[name] for name in self.fit}

    def to_x(self, values: Mapping) -> np.ndarray:
        return np.array([np.log(values[n]) if PARAMETERS[n][1] else values[n] for n in self.fit])

    def values(self, x) -> dict:
        return {
            n: float(np.exp(v)) if PARAMETERS[n][1] else float(v)
            for n, v in zip(self.fit, x, strict=True)
        }

    def rod_and_angle(self, values: Mapping) -> tuple[Rod, float]:
        rod = self.rod
        if "youngs_modulus" in values:
            rod = dataclasses.replace(rod, youngs_modulus=values["youngs_modulus"])
        if "magnitude" in values:
            m = rod.magnetization
            angle = float(m.angle(np.zeros(1))[0])
            elevation = float(m.elevation(np.zeros(1))[0])
            rod = dataclasses.replace(
                rod,
                magnetization=Magnetization(values["magnitude"], angle, elevation, label=m.label),
            )
        return rod, values.get("field_angle", self.field_angle)

    # -- solves ---------------------------------------------------------------------------------
    def solve(self, rod: Rod, angle: float, group: _Group, magnitudes: np.ndarray):
        """RodResult of ``rod`` along the group's direction (turned by ``angle``) at the
        field magnitudes (ascending), and the field parameter B (3,) of the path."""
        b_ref = float(group.magnitudes.max())
        B = b_ref * (about_z(angle) @ group.direction)
        field = coils.UniformField(B=B)
        self.solves += 1
        try:
            result = solve_rod(rod, field, magnitudes / b_ref, **self.options)
        except ConvergenceError as err:
            raise ConvergenceError(
                f"calibrate: the model could not be solved at E = {rod.youngs_modulus:.6g} Pa, "
                f"|M| = {rod.magnetization.max_magnitude(rod.length):.6g} A/m, field "
                f"direction {np.round(B / b_ref, 6).tolist()} (misalignment {angle:.3g} rad), "
                f"|B| up to {magnitudes.max():.4g} T: {err}",
                reached=err.reached * b_ref,
                target=err.target * b_ref,
                residual=err.residual,
            ) from err
        return result, B

    def evaluate(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(model outputs (k,), d outputs / d x (k, p)) at fit variables ``x``."""
        x = np.asarray(x, float)
        key = x.tobytes()
        if key in self._cache:
            return self._cache[key]
        values = self.values(x)
        rod, angle = self.rod_and_angle(values)
        wrt = []
        if "youngs_modulus" in self.fit:
            wrt.append("youngs_modulus")
        if "magnitude" in self.fit:
            wrt.append("magnitudes")
        if "field_angle" in self.fit:
            wrt.append("B")
        out = np.empty(self.k)
        jac = np.empty((self.k, len(self.fit)))
        for group in self.groups:
            order = np.argsort(group.magnitudes, kind="stable")
            rows = group.rows[order]
            result, B = self.solve(rod, angle, group, group.magnitudes[order])
            _check_stable(result, group.magnitudes[order], B)
            labels, _, _, D = tip_derivatives(result, np.arange(rows.size), wrt)
            D = D[:, self.row]  # (g, q) per unit of each physical parameter
            tips = result.tip_angle if self.row == 3 else result.tip[:, self.row]
            out[rows] = tips
            for j, name in enumerate(self.fit):
                if name == "youngs_modulus":
                    col = D[:, labels.index("youngs_modulus")] * values[name]
                elif name == "magnitude":
                    col = D[:, labels.index("magnitudes[0]")] * values[name]
                else:  # d B / d angle = e_z x B
                    dB = np.array([-B[1], B[0], 0.0])
                    col = D[:, [labels.index(f"B[{i}]") for i in range(3)]] @ dB
                jac[rows, j] = col
        if len(self._cache) > 16:
            self._cache.clear()
        self._cache[key] = (out, jac)
        return out, jac


def _check_stable(result, magnitudes, B):
    bad = np.flatnonzero(~np.asarray(result.stable, bool))
    if bad.size:
        b = magnitudes[bad[0]]
        direction = np.round(B / np.linalg.norm(B), 6).tolist()
        raise UnstableStateError(
            f"the model state at |B| = {b:.4g} T along {direction} is unstable: the rod has "
            "passed a bifurcation on its straight (symmetric) branch, where no experiment can "
            "stay (a field antiparallel to the magnetization buckles the rod to one side "
            "through a pitchfork).  Model the imperfection that selects the side: a small "
            "field misalignment, field_angle=..., fixed or fitted"
        )


def _check_rank(jac: np.ndarray, fit: tuple, rank_tol: float, where: str) -> None:
    """IdentifiabilityError if the (weighted) Jacobian (k, p) is numerically rank deficient."""
    norms = np.linalg.norm(jac, axis=0)
    for name, n in zip(fit, norms, strict=True):
        if not n > 0:
            raise IdentifiabilityError(
                f"{name} has no effect on the model at these fields ({where}: its Jacobian "
                "column is zero), so the data cannot determine it; leave it out of fit"
            )
    if len(fit) == 1:
        return
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    ratio = s[-1] / s[0]
    if ratio >= rank_tol:
        return
    v = vt[-1]
    involved = [n for n, c in zip(fit, v, strict=True) if abs(c) > 0.1]
    msg = (
        f"the fit is rank deficient ({where}): the Jacobian columns of {involved} are "
        f"linearly dependent (smallest / largest singular value of the column-normalised "
        f"Jacobian {ratio:.2g} < rank_tol {rank_tol:g}), so the data cannot determine them "
        "separately and a least-squares 'solution' would be an arbitrary point of a ridge."
    )
    if {"youngs_modulus", "magnitude"} <= set(involved):
        msg += (
            "  In a uniform field (and without gravity) the equilibrium depends on E and |M| "
            "only through lambda = A |M| |B| L^2 / (E I), i.e. through |M| / E: "
            "dtip/dE = -(|M| / E) dtip/d|M| exactly.  Fix one of them: e.g. |M| = Br / mu0 "
            "from the measured remanence (Br = 0.143 T gives 114 kA/m) and fit "
            "youngs_modulus alone, or E from a tensile test and fit magnitude alone."
        )
    else:
        msg += "  Fix all but one of them."
    raise IdentifiabilityError(msg)


@dataclass(frozen=True, repr=False)
class Calibration:
    """Result of :func:`calibrate`.

    Attributes
    ----------
    parameters : tuple of str, length p
        The fitted parameters, in the order of ``fit``.
    values : dict
        Fitted value of each parameter (SI: Pa, A/m, rad).
    initial : dict
        Starting value of each parameter.
    standard_errors : dict
        One standard error of each fitted value (same unit), from the covariance.
    covariance : ndarray, shape (p, p)
        ``s^2 (J^T W J)^-1`` in the parameters' units, with J = d model / d parameter at the
        fit, W = diag(1 / sigma^2) and s^2 = (weighted residual sum of squares) / (k - p).
    rod : Rod
        The rod with the fitted modulus and magnetization.
    field_angle : float
        Misalignment of every field (rotation about z), rad: fitted, or the fixed value.
    fields : ndarray, shape (k, 3)
        The applied fields as given (before the misalignment rotation), T.
    output : str
        The measured quantity (``"tip_x"``, ``"tip_y"`` in m, ``"tip_angle"`` in rad).
    measured : ndarray, shape (k,)
        The data (unit of ``output``).
    model : ndarray, shape (k,)
        The fitted model at the data's fields.
    residuals : ndarray, shape (k,)
        ``model - measured`` (unit of ``output``; m for tips).
    sigma : ndarray, shape (k,), or None
        The relative uncertainties used as weights (None: unweighted).
    jacobian : ndarray, shape (k, p)
        d model / d parameter at the fit (output unit per parameter unit).
    cost : float
        ``0.5 * sum((residuals / sigma)^2)`` (sigma = 1 if unweighted).
    nfev, njev : int
        Residual and Jacobian evaluations of the least-squares solver.
    solves : int
        Forward path solves (:func:`coilrod.solve_rod` calls) of the fit, one per field
        direction per distinct parameter point (the Jacobian reuses its point's solve).
    rejected : tuple of str
        Why each rejected trial point failed (the model could not be solved there, or a
        state was unstable or singular); the solver shrank its trust region and went on.
    status : int
        :func:`scipy.optimize.least_squares` status (> 0: converged).
    message : str
    solve_options : dict
        The options the model was solved with.
    """

    parameters: tuple
    values: dict
    initial: dict
    standard_errors: dict
    covariance: np.ndarray
    rod: Rod
    field_angle: float
    fields: np.ndarray
    output: str
    measured: np.ndarray
    model: np.ndarray
    residuals: np.ndarray
    sigma: np.ndarray | None
    jacobian: np.ndarray
    cost: float
    nfev: int
    njev: int
    solves: int
    rejected: tuple
    status: int
    message: str
    solve_options: dict

    @property
    def success(self) -> bool:
        """True if the least-squares solver met a tolerance."""
        return self.status > 0

    @property
    def dof(self) -> int:
        """Degrees of freedom of the residuals, k - p."""
        return self.measured.size - len(self.parameters)

    @property
    def rms(self) -> float:
        """Root-mean-square residual (unit of ``output``)."""
        return float(np.sqrt(np.mean(self.residuals**2)))

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the fitted parameters, shape (p, p)."""
        d = np.sqrt(np.diag(self.covariance))
        return self.covariance / np.outer(d, d)

    @property
    def remanence(self) -> float:
        """mu0 |M| of the fitted rod (maximum over the rod), T."""
        return mu_0 * self.rod.magnetization.max_magnitude(self.rod.length)

    def model_curve(self, samples: int = 101) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The fitted model along each field direction of the data, from zero to the largest
        field measured.

        Parameters
        ----------
        samples : int
            Field magnitudes per direction (>= 2).

        Returns
        -------
        list of (direction, magnitudes, values)
            One per direction: the unit vector (3,) as given (before the misalignment), |B|
            (samples,) in T and the model output (samples,).
        """
        samples = as_count(samples, "samples", 2)
        model = _Model(self.rod, self.fields, self.output, (), self.field_angle, self.solve_options)
        out = []
        for group in model.groups:
            b = np.linspace(0.0, group.magnitudes.max(), samples)
            result, _ = model.solve(self.rod, self.field_angle, group, b)
            row = OUTPUTS[self.output][1]
            values = result.tip_angle if row == 3 else result.tip[:, row]
            out.append((group.direction, b, np.asarray(values, float).copy()))
        return out

    def plot(self, ax=None, *, per_length: bool = False, samples: int = 101):
        """Measured points and the fitted model against |B| (mT).

        Parameters
        ----------
        ax : matplotlib Axes, optional
        per_length : bool
            Divide tip positions by the rod length (delta / L).
        samples : int
            Points of the model curve per field direction.

        Returns
        -------
        matplotlib Axes
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5.5, 4))
        unit, label = 1.0, f"{self.output} (rad)"
        if self.output != "tip_angle":
            unit, label = (
                (self.rod.length, f"{self.output} / L")
                if per_length
                else (1e-3, f"{self.output} (mm)")
            )
        norms = np.linalg.norm(self.fields, axis=1)
        ax.plot(norms * 1e3, self.measured / unit, "o", color="k", mfc="none", label="measured")
        curves = self.model_curve(samples)
        for i, (direction, b, values) in enumerate(curves):
            name = "model" if len(curves) == 1 else f"model, {np.round(direction, 3).tolist()}"
            ax.plot(b * 1e3, values / unit, "-", color=f"C{i}", label=name)
        ax.set_xlabel("|B| (mT)")
        ax.set_ylabel(label)
        ax.legend()
        return ax

    def summary(self) -> str:
        """The fitted parameters, their standard errors and the residuals, as a text table."""
        rows = [f"Calibration of {self.output} ({self.measured.size} points, {self.dof} dof)"]
        for name in self.parameters:
            unit = PARAMETERS[name][0]
            rows.append(
                f"  {name:>15s} = {self.values[name]:.6g} +- {self.standard_errors[name]:.3g} "
                f"{unit} (start {self.initial[name]:.6g})"
            )
        unit = OUTPUTS[self.output][0]
        rows.append(
            f"  rms residual {self.rms:.4g} {unit}, max |residual| "
            f"{np.abs(self.residuals).max():.4g} {unit}, cost {self.cost:.4g}"
        )
        rows.append(
            f"  {self.nfev} evaluations, {self.njev} Jacobians, {self.solves} path solves, "
            f"{len(self.rejected)} trial points rejected; "
            f"{self.message}"
        )
        return "\n".join(rows)

    def __repr__(self) -> str:
        return self.summary()


def _check_fit(fit, rod: Rod) -> tuple:
    if isinstance(fit, str):
        fit = (fit,)
    try:
        fit = tuple(fit)
    except TypeError:
        raise ValueError(
            f"fit must be a parameter name or a sequence of them; got {fit!r}"
        ) from None
    if not fit:
        raise ValueError(f"fit must name at least one parameter of {sorted(PARAMETERS)}")
    for name in fit:
        as_choice(name, "each entry of fit", tuple(PARAMETERS))
    if len(set(fit)) != len(fit):
        raise ValueError(f"fit names a parameter twice: {list(fit)}")
    if "magnitude" in fit:
        m = rod.magnetization
        if not m.is_constant:
            raise ValueError(
                "fitting magnitude needs a constant magnetization (one |M| and one angle); "
                f"the rod has {m!r}"
            )
        if not m.magnitude(np.zeros(1))[0] > 0:
            raise ValueError(
                "fitting magnitude needs a positive starting |M| (it is fitted in log); got "
                f"{m.magnitude(np.zeros(1))[0]:g} A/m (turn the angle by pi for the opposite "
                "direction)"
            )
    return fit


def _check_bounds(bounds, fit, initial) -> tuple[np.ndarray, np.ndarray]:
    lo = np.full(len(fit), -np.inf)
    hi = np.full(len(fit), np.inf)
    if bounds is None:
        return lo, hi
    if not isinstance(bounds, Mapping):
        raise ValueError(f"bounds must be a dict {{name: (low, high)}}; got {bounds!r}")
    for name, pair in bounds.items():
        if name not in fit:
            raise ValueError(f"bounds names {name!r}, which is not fitted (fit = {list(fit)})")
        b = np.asarray(pair, dtype=float) if not isinstance(pair, str) else None
        if b is None or b.shape != (2,) or np.isnan(b).any() or not b[0] < b[1]:
            raise ValueError(f"bounds[{name!r}] must be (low, high) with low < high; got {pair!r}")
        j = fit.index(name)
        if not b[0] < initial[name] < b[1]:
            raise ValueError(
                f"the starting {name} = {initial[name]:.6g} lies outside bounds[{name!r}] = "
                f"({b[0]:g}, {b[1]:g})"
            )
        if PARAMETERS[name][1]:
            if b[0] < 0:
                raise ValueError(
                    f"bounds[{name!r}] must be non-negative ({name} is positive); got {pair!r}"
                )
            with np.errstate(divide="ignore"):
                b = np.log(b)
        lo[j], hi[j] = b
    return lo, hi


def _checked_data(rod, fields, measured, fit, output, field_angle, sigma):
    """Validate the data of :func:`calibrate`: (fields (k, 3), measured (k,), output, fit,
    field_angle, weights (k,) = 1 / sigma)."""
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    rod.magnetization.check_planar("calibration (planar rod)")
    fields = as_array(fields, "fields", ("k", 3))
    k = fields.shape[0]
    measured = as_array(measured, "measured", ("k",))
    if measured.size != k:
        raise ValueError(
            f"measured must have one value per field, shape ({k},); got {measured.shape}"
        )
    norms = np.linalg.norm(fields, axis=1)
    if np.any(np.abs(fields[:, 2]) > 1e-12 * norms):
        raise ValueError(
            "fields must lie in the bending plane (B_z = 0): the planar rod ignores B_z; got "
            f"B_z = {fields[np.argmax(np.abs(fields[:, 2])), 2]:g} T"
        )
    output = as_choice(output, "output", tuple(OUTPUTS))
    fit = _check_fit(fit, rod)
    p = len(fit)
    if k < p + 1:
        raise ValueError(
            f"fitting {p} parameter(s) needs at least {p + 1} data points (the residual "
            f"variance is estimated from k - p degrees of freedom); got {k}"
        )
    field_angle = finite_scalar(field_angle, "field_angle")
    if sigma is None:
        weights = np.ones(k)
    else:
        s = as_array(sigma, "sigma")
        if s.ndim > 1 or s.size not in (1, k):
            raise ValueError(f"sigma must be a number or have shape ({k},); got {s.shape}")
        if not np.all(s > 0):
            raise ValueError(f"sigma must be positive; got {s.ravel().tolist()}")
        weights = 1.0 / np.broadcast_to(s.ravel(), (k,))
    return fields, measured, output, fit, field_angle, weights


def _check_reach(rod: Rod, measured: np.ndarray, output: str, options: dict) -> None:
    """A measured tip coordinate farther from the clamp than the rod's length is no state of
    the rod (the fit would drive E towards zero and report it): ValueError naming
    ``measured`` (in m; data in mm are 1000 times too far)."""
    if output not in ("tip_x", "tip_y"):
        return
    clamp = np.asarray(options.get("clamp_position", (0.0, 0.0, 0.0)), dtype=float)
    if clamp.shape != (3,):  # solve_rod names the bad clamp_position
        return
    off = np.abs(measured - clamp[OUTPUTS[output][1]])
    worst = int(np.argmax(off))
    if off[worst] > rod.length * (1 + 1e-9):
        raise ValueError(
            f"measured[{worst}] = {measured[worst]:g} m puts the tip {off[worst]:g} m from the "
            f"clamp along {output[-1]}, beyond the rod's length {rod.length:g} m (measured is "
            "in m: data in mm?)"
        )


def _least_squares(model, measured, weights, x0, bounds, rank_tol, tol, max_nfev):
    """scipy's trust-region least squares of the weighted residuals with the model's exact
    Jacobian from ``x0``: (its solution, the trial points rejected and why).  The rank of the
    Jacobian is checked at the start."""
    k = measured.size
    fit = model.fit
    lo, hi = bounds
    # the solver sees residuals of order one (its gtol is absolute): divided by the data's size
    ref = float(np.max(np.abs(measured * weights))) or 1.0

    rejected = []

    def residuals(x):
        try:
            q = model.evaluate(x)[0]
        except (ConvergenceError, SingularStateError, UnstableStateError) as err:
            if np.array_equal(x, x0):
                raise
            rejected.append(f"{model.values(x)}: {err}")
            return np.full(k, np.nan)  # a trial step off the model's domain: trf backs off
        return (q - measured) * weights / ref

    def jacobian(x):
        return model.evaluate(x)[1] * weights[:, None] / ref

    _check_rank(jacobian(x0), fit, rank_tol, "at the starting values")
    from scipy.optimize import least_squares

    sol = least_squares(
        residuals,
        x0,
        jac=jacobian,
        bounds=(lo, hi),
        method="trf",
        x_scale=1.0,
        ftol=tol,
        xtol=tol,
        gtol=tol,
        max_nfev=max_nfev,
    )
    return sol, rejected


def _calibration(model, sol, rejected, initial, data, rank_tol):
    """The Calibration at the least-squares solution ``sol``: values, covariance
    ``s^2 (J^T W J)^-1`` in the parameters themselves (rank checked at the fit); ``data`` is
    (fields, output, measured, weights, sigma)."""
    fields, output, measured, weights, sigma = data
    fit, options = model.fit, model.options
    k, p = measured.size, len(fit)
    values = model.values(sol.x)
    q, jac_x = model.evaluate(sol.x)
    _check_rank(jac_x * weights[:, None], fit, rank_tol, "at the fitted values")
    scale = np.array([values[n] if PARAMETERS[n][1] else 1.0 for n in fit])
    jac = jac_x / scale  # per unit of the parameters themselves
    r = (q - measured) * weights
    cost = 0.5 * float(r @ r)
    _, s, vt = np.linalg.svd(jac * weights[:, None], full_matrices=False)
    covariance = (vt.T / s**2) @ vt * (2 * cost / (k - p))
    fitted_rod, angle = model.rod_and_angle(values)
    return Calibration(
        parameters=fit,
        values=values,
        initial=initial,
        standard_errors={n: float(np.sqrt(covariance[j, j])) for j, n in enumerate(fit)},
        covariance=covariance,
        rod=fitted_rod,
        field_angle=float(angle),
        fields=fields.copy(),
        output=output,
        measured=measured.copy(),
        model=q.copy(),
        residuals=q - measured,
        sigma=None if sigma is None else 1.0 / weights,
        jacobian=jac,
        cost=cost,
        nfev=int(sol.nfev),
        njev=int(sol.njev),
        solves=model.solves,
        rejected=tuple(rejected),
        status=int(sol.status),
        message=str(sol.message),
        solve_options=options,
    )


def _check_radians(measured: np.ndarray, output: str, field_angle: float, options) -> None:
    """Angles in degrees where radians are meant, where the numbers show it: a measured tip
    angle more than a full turn (2 pi) from the clamp's angle (a planar rod curled through
    more than one turn), or a field misalignment beyond a full turn: ValueError naming the
    argument and saying "radians".  Angles within a turn pass (small angles in degrees
    cannot be told from radians)."""
    turn = 2 * np.pi * (1 + 1e-12)
    if abs(field_angle) > turn:
        raise ValueError(
            f"field_angle = {field_angle:g} rad is more than a full turn: it is in radians "
            f"(degrees? {field_angle:g} deg = {np.radians(field_angle):.4g} rad)"
        )
    if output != "tip_angle":
        return
    try:
        clamp = float(options.get("clamp_angle", 0.0))
    except (TypeError, ValueError):  # solve_rod names the bad clamp_angle
        return
    off = np.abs(measured - clamp)
    worst = int(np.argmax(off))
    if off[worst] > turn:
        raise ValueError(
            f"measured[{worst}] = {measured[worst]:g} rad puts the tip tangent {off[worst]:g} "
            f"rad from the clamp's angle {clamp:g} rad, more than a full turn: tip_angle data "
            f"are in radians (degrees? {measured[worst]:g} deg = "
            f"{np.radians(measured[worst]):.4g} rad)"
        )


def calibrate(
    rod: Rod,
    fields,
    measured,
    *,
    fit: Sequence[str] | str = ("youngs_modulus",),
    output: str = "tip_y",
    field_angle: float = 0.0,
    sigma=None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    rank_tol: float = 1e-6,
    tol: float = 1e-10,
    max_nfev: int = 50,
    solve_options: Mapping | None = None,
) -> Calibration:
    """Fit rod parameters to measured tip outputs in uniform fields (nonlinear least squares
    with the exact adjoint Jacobian).

    Parameters
    ----------
    rod : Rod
        The rod; its modulus and magnetization are the starting values (and the fixed values
        of what is not fitted).
    fields : array-like, shape (k, 3)
        Applied uniform fields, T, in the bending plane (B_z = 0).  Fields along one
        direction are solved as one load path from zero; several directions are allowed.  A
        zero field is the straight rod.
    measured : array-like, shape (k,)
        The measured output at each field: m for ``"tip_x"`` / ``"tip_y"``, rad for
        ``"tip_angle"``.
    fit : str or sequence of str
        Parameters to fit (default E alone):

        * ``"youngs_modulus"``: E, Pa (fitted as log E, so it stays positive);
        * ``"magnitude"``: |M| of a constant magnetization, A/m (log |M|);
        * ``"field_angle"``: a misalignment of every field, rad, counter-clockwise about z
          (the imperfection of a field antiparallel to the magnetization).

        E and |M| together are not identifiable (see Notes): that raises.
    output : {"tip_y", "tip_x", "tip_angle"}
        What was measured.
    field_angle : float
        Misalignment of the fields, rad: fixed, or the start if fitted.
    sigma : float or array-like, shape (k,), optional
        Relative uncertainties of the data (weights ``1 / sigma^2``; the covariance is
        rescaled by the residual variance, so only their ratios matter).  Default: equal.
    bounds : dict, optional
        ``{name: (low, high)}`` in the parameter's unit; ``inf`` for no bound.
    rank_tol : float
        Smallest accepted ratio of the smallest to the largest singular value of the
        column-normalised weighted Jacobian, checked at the start and at the fit.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of :func:`scipy.optimize.least_squares`.
    max_nfev : int
        Most residual evaluations (each: one path solve per field direction).
    solve_options : dict, optional
        Passed to :func:`coilrod.solve_rod`: ``nodes``, ``richardson``, ``tol``,
        ``max_iter``, ``clamp_position``, ``clamp_angle``.

    Returns
    -------
    Calibration
        Fitted values, standard errors, covariance, residuals (k,), the model, cost,
        evaluation counts, ``plot()``.

    Raises
    ------
    ValueError
        Bad input (shapes, NaN, non-positive values, unknown names, fewer than p + 1 points,
        a measured tip x or y farther from the clamp than the rod's length, a measured tip
        angle more than a full turn from the clamp's or a ``field_angle`` beyond a full
        turn: angles in degrees);
        a magnetization with an out-of-plane elevation (the planar rod is fitted).
    IdentifiabilityError
        (a ValueError) The Jacobian is rank deficient at the start or at the fit: the data
        cannot separate the parameters (E and |M| always; a parameter with no effect).
    UnstableStateError
        (a ValueError) At the starting values, a state is unstable: the straight branch past
        a bifurcation (a field antiparallel to the magnetization; set ``field_angle``).
    coilrod.ConvergenceError
        The model could not be solved at the starting values (the message gives the
        parameters and the field).
    coilrod.SingularStateError
        At the starting values, a data point lies exactly at a bifurcation or fold.

    A trial point of the solver where one of the last three happens is rejected instead
    (its residuals count as infinite, the trust region shrinks; ``Calibration.rejected``
    says why).

    Warns
    -----
    RuntimeWarning
        The least-squares solver stopped at ``max_nfev`` without meeting a tolerance.

    Notes
    -----
    Minimises ``0.5 sum_i ((q_i(p) - measured_i) / sigma_i)^2`` over the fitted parameters
    p, where q_i is the output of :func:`coilrod.solve_rod` at field i (planar rod,
    inextensible and unshearable).  The residuals' Jacobian is exact: the batched adjoint
    derivatives of every state of a path (:mod:`coilrod.design.sensitivity`), for the field
    angle chained through dB/d(angle) = e_z x B.  Positive parameters are fitted in log
    (the Jacobian is multiplied by the value); the reported covariance is in the parameters
    themselves, ``s^2 (J^T W J)^-1``, linearised at the fit, s^2 = 2 cost / (k - p).

    E and |M| enter the equilibrium only through lambda = A |M| |B| L^2 / (E I) (the load is
    linear in |M|, the stiffness in E), so tip-against-field data fix |M| / E and no more:
    fit one of them with the other fixed.  The rank check also catches a parameter with no
    effect (e.g. ``field_angle`` when every field is zero).

    Examples
    --------
    >>> import numpy as np
    >>> import coils, coilrod
    >>> rod = coilrod.Rod(0.0172, 9e5, coilrod.Rectangle(5e-3, 0.84e-3),
    ...                   coilrod.Magnetization(114e3, 0.0))
    >>> fields = np.array([[0.0, b, 0.0] for b in (2e-3, 5e-3, 10e-3, 20e-3)])
    >>> truth = coilrod.solve_rod(rod, coils.UniformField(B=(0, 20e-3, 0)),
    ...                           [0.1, 0.25, 0.5, 1.0]).tip[:, 1]
    >>> start = coilrod.Rod(0.0172, 2e6, rod.section, rod.magnetization)
    >>> cal = coilrod.calibrate(start, fields, truth)
    >>> round(cal.values["youngs_modulus"] / 9e5, 9)
    1.0
    """
    fields, measured, output, fit, field_angle, weights = _checked_data(
        rod, fields, measured, fit, output, field_angle, sigma
    )
    rank_tol = positive(rank_tol, "rank_tol")
    tol = positive(tol, "tol")
    max_nfev = as_count(max_nfev, "max_nfev", 1)
    options = dict(solve_options or {})
    for key in options:
        if key not in SOLVE_OPTIONS:
            raise ValueError(f"solve_options may set {list(SOLVE_OPTIONS)}; got {key!r}")

    _check_reach(rod, measured, output, options)
    _check_radians(measured, output, field_angle, options)
    model = _Model(rod, fields, output, fit, field_angle, options)
    initial = model.initial()
    lo, hi = _check_bounds(bounds, fit, initial)
    sol, rejected = _least_squares(
        model, measured, weights, model.to_x(initial), (lo, hi), rank_tol, tol, max_nfev
    )
    if sol.status == 0:
        warnings.warn(
            f"calibrate: least_squares stopped after max_nfev = {max_nfev} evaluations without "
            "meeting its tolerances; the values are not converged",
            RuntimeWarning,
            stacklevel=2,
        )
    data = (fields, output, measured, weights, sigma)
    return _calibration(model, sol, rejected, initial, data, rank_tol)
