"""``solve_fem``: validate the inputs, build mesh and assembler, run the continuation."""

from __future__ import annotations

import warnings

import numpy as np

from coilrod.robot.rod import Rod
from coils._validate import finite_scalar
from coils.field import Field

from ..errors import ConvergenceError
from ..path.corrector import NewtonOptions
from ..path.events import StabilityWarning, warn_events
from ..path.stepping import PathOptions, follow_load
from ..rod.model import clamp_frame, planar_reasons
from .assembly import Assembler
from .material import moduli
from .mesh import (
    check_elements,
    check_memory,
    check_mesh,
    default_elements,
    rod_mesh,
    ungraded_clamp,
)
from .problem import FEMProblem
from .result import FEMResult

__all__ = ["solve_fem", "DEFAULT_POISSON_RATIO"]

#: Poisson's ratios closer to 0.5 than this are refused: K/G ~ 5e9 and beyond, where the
#: Newton solve stalls at round-off (0.5 - 1e-11 could not leave scale 0).
NU_GAP = 1e-10
#: Below this Poisson's ratio solve_fem warns: the elements lock (dilatational locking, G/K > 6).
NU_LOCKING = -0.5

#: Default Poisson's ratio: K/G = 2(1 + nu) / (3(1 - 2 nu)) = 999.7, nearly incompressible
#: like the elastomers of Zhao et al. (2019), who take K >> G.
DEFAULT_POISSON_RATIO = 0.4995


def _scales(scales) -> np.ndarray:
    if isinstance(scales, str | bytes):
        raise ValueError(f"scales must be a sequence of numbers; got {scales!r}")
    try:
        arr = np.atleast_1d(np.asarray(scales, dtype=float))
    except (TypeError, ValueError):
        raise ValueError(f"scales must be a sequence of numbers; got {scales!r}") from None
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"scales must be a non-empty 1D sequence; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"scales must be finite; got {arr.tolist()}")
    return arr


def _checked_options(
    rod, field, dim, order, plane, formulation, poisson_ratio, rtol, utol, max_iterations, max_cuts
) -> float:
    """Validate the options of :func:`solve_fem` (a 2D problem: that the field and the rod stay
    in the plane); returns the Poisson ratio."""
    if isinstance(dim, bool) or dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3; got {dim!r}")
    if dim == 2:
        rod.magnetization.check_planar("2D FEM (dim=2)")
        reasons = planar_reasons(rod, field, np.zeros(3), clamp_frame(0.0, None))
        if reasons:
            raise ValueError(
                "dim=2 would drop out-of-plane loads (the 2D FEM sees only B_x, B_y and their "
                "x-y derivatives): " + "; ".join(reasons) + " -- use dim=3"
            )
    if isinstance(order, bool) or order not in (1, 2):
        raise ValueError(f"order must be 1 or 2; got {order!r}")
    if plane not in ("stress", "strain"):
        raise ValueError(f"plane must be 'stress' or 'strain'; got {plane!r}")
    if formulation not in ("mixed", "displacement"):
        raise ValueError(f"formulation must be 'mixed' or 'displacement'; got {formulation!r}")
    nu = finite_scalar(poisson_ratio, "poisson_ratio")
    if not -1.0 < nu < 0.5:
        raise ValueError(f"poisson_ratio must lie in (-1, 0.5); got {nu}")
    if nu > 0.5 - NU_GAP:
        raise ValueError(
            f"poisson_ratio = {nu!r} is within {NU_GAP:g} of 0.5 (K/G = "
            f"{2 * (1 + nu) / (3 * (1 - 2 * nu)):.3g}): beyond what float64 solves; 0.4999999 "
            "gives the same tips to 1e-8"
        )
    if nu < NU_LOCKING:
        warnings.warn(
            f"poisson_ratio = {nu:g} < {NU_LOCKING:g}: the elements lock as nu -> -1 (G/K = "
            f"{3 * (1 - 2 * nu) / (2 * (1 + nu)):.3g}; the mixed formulation relieves K >> G, "
            "not G >> K): the body is too stiff by a mesh-dependent amount (at nu = -0.9 a "
            "slender rod's tip under a small load is 0.74 and 0.92 of its lambda L / 3 on "
            "(4, 1, 1) and (16, 2, 2) elements); refine the mesh until the tip stops moving",
            UserWarning,
            stacklevel=3,
        )
    for name, val in (("rtol", rtol), ("utol", utol)):
        if not finite_scalar(val, name) > 0:
            raise ValueError(f"{name} must be positive; got {val}")
    for name, val, high in (("max_iterations", max_iterations, 1000), ("max_cuts", max_cuts, 60)):
        if isinstance(val, bool) or not isinstance(val, int | np.integer) or not 1 <= val <= high:
            raise ValueError(f"{name} must be an integer from 1 to {high}; got {val!r}")
    return nu


def _assembler(rod, field, mesh, elements, dim, order, nu, plane, formulation) -> Assembler:
    """The Assembler of the rod's body on ``mesh`` (the default or given element counts'
    mesh when None), checked to have a finite field on the undeformed body."""
    if mesh is None:
        if elements is None:
            elements = default_elements(rod, dim)
        elements = check_elements(elements, dim)
        check_memory(rod.section, dim, order, elements, rod.length)
        mesh = rod_mesh(rod, dim, elements, order)
    elif getattr(getattr(mesh, "p", None), "shape", (dim,))[0] != dim:
        raise ValueError(f"mesh must be {dim}-dimensional for dim={dim}; got {mesh.p.shape[0]}")
    else:
        check_mesh(mesh, rod, dim, order)
        if dim == 3 and (problem := ungraded_clamp(mesh, rod.section)):
            warnings.warn(problem, StabilityWarning, stacklevel=3)
    G, K = moduli(rod.youngs_modulus, nu)
    asm = Assembler(mesh, order, rod, field, G, K, plane=plane, mixed=formulation == "mixed")
    # the field must be finite on the undeformed body
    try:
        B, Gr, _ = asm.field_at(asm.X.reshape(-1, dim), False)
    except ValueError as exc:
        raise ValueError(f"field cannot be evaluated on the undeformed rod body: {exc}") from None
    if not (np.all(np.isfinite(B)) and (Gr is None or np.all(np.isfinite(Gr)))):
        raise ValueError("field must be finite on the rod body; it returned non-finite values")
    return asm


def _progress(progress, total: int, dim: int):
    """(callback (k, scale) or None, the tqdm bar to close or None) for ``progress``: True (a
    bar), False/None, or a callable."""
    bar = None
    if progress is True:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc=f"solve_fem {dim}D", unit="scale")

        def progress(k, scale):
            bar.update(1)
            bar.set_postfix(scale=f"{scale:.3g}")

    elif not progress:
        progress = None
    elif not callable(progress):
        raise ValueError(f"progress must be a bool or a callable; got {progress!r}")
    return progress, bar


def solve_fem(
    rod: Rod,
    field: Field,
    scales,
    dim: int = 3,
    order: int = 2,
    elements=None,
    *,
    poisson_ratio: float = DEFAULT_POISSON_RATIO,
    plane: str = "stress",
    formulation: str = "mixed",
    mesh=None,
    rtol: float = 1e-8,
    utol: float = 1e-6,
    max_iterations: int = 25,
    max_cuts: int = 16,
    progress=None,
) -> FEMResult:
    """Large-deformation equilibria of a hard-magnetic neo-Hookean rod body (FEM).

    Parameters
    ----------
    rod : coilrod.Rod
        Length L (m), Young's modulus E (Pa), section and magnetization; the body is
        ``[0, L]`` along x with the section centred on the x axis, clamped at x = 0.
    field : coils.Field
        Applied field (T) at scale 1; evaluated at the deformed positions.
    scales : sequence of float, shape (n,)
        Field multipliers, continued in order from the unloaded state.
    dim : {2, 3}
        2D over length x thickness (plane stress by default) or 3D over the section.  2D
        refuses (ValueError) what would leave the plane z = 0, by the planar rod model's
        criterion (:func:`coilrod.rod.model.planar_reasons`, clamp at the origin along +x): a
        non-planar magnetization (an elevation), or a field with B_z or dB_z/dx, dB_z/dy on
        the disc of radius L around the clamp.
    order : {1, 2}
        Element order (quadrilaterals/hexahedra); quadratic by default (linear ones lock in
        bending and converge slowly).  A 3D Circle is meshed with quadratic geometry for
        order 2 and by the linear mesh of the same O-grid vertices (a polygonal section) for
        order 1, which then needs ``core >= 2``.
    elements : tuple of int, optional
        Elements along (length, thickness) in 2D and (length, thickness, width) for a 3D
        Rectangle; for a 3D Circle (length, core, ring): ``core`` elements along each side
        of the O-grid's central square (``4 core`` arcs around the circumference) and
        ``ring`` radial layers.  Default :func:`~coilrod.fem.default_elements`: (20, 1) in 2D,
        (20, 1, 1) in 3D and (20, 2, 1) for a 3D Circle.  The element layers along the length
        end at the magnetization's breakpoints (piecewise uniform; ``elements[0]`` layers in
        all, at least one per piece; :func:`~coilrod.fem.length_layers`), so no element
        straddles a jump of |M| or of its angle.  In 3D the layers are graded at the clamp,
        halved there until each is no longer than the larger of the section's smallest extent
        (a side, the diameter) and twice its distance from the clamp: about
        ``log2(L / (elements[0] side))`` layers more (none for the default (20, 1, 1) of a
        section of L/20).  On
        layers long against the section at the clamp the stability count is a property of the
        mesh: a rod in pure tension (it cannot buckle) was reported unstable at small loads.
    poisson_ratio : float
        nu in (-1, 0.5 - 1e-10]; sets G = E / (2(1 + nu)) and K = E / (3(1 - 2 nu)).  The
        continuum's own value, independent of ``rod.poisson_ratio`` (the rod's torsional
        stiffness, which may be the incompressible 0.5 that K cannot take).  Below -0.5 a
        UserWarning: the elements lock as nu -> -1 (G >> K), too stiff by a mesh-dependent
        amount.
    plane : {"stress", "strain"}
        2D assumption.  Plane stress has the rod's bending stiffness E I; plane strain is
        stiffer by 1/(1 - nu^2).  In 2D a Circle section is the strip of equal I/A
        (height sqrt(3) D / 2).
    formulation : {"mixed", "displacement"}
        "mixed" (default): displacement/pressure with a discontinuous pressure (linear per
        element for order 2, constant for order 1) condensed element by element; free of
        volumetric locking.  "displacement": plain neo-Hookean displacement elements.
        Plane stress has no volumetric constraint and always uses displacements.
    mesh : skfem.Mesh, optional
        A reference mesh to use instead of the generated one: MeshQuad1/2 in 2D, MeshHex1/2
        in 3D (of linear geometry for ``order=1``), spanning x in [0, L] with facets on x = 0
        and x = L, within the section's bounds about the x axis and filling its area
        (:func:`~coilrod.fem.mesh.check_mesh`; else ValueError saying what is off).  A 3D
        mesh with layers near the clamp more than twice as long as that grading allows gets a
        StabilityWarning (its stability count is unreliable;
        :func:`~coilrod.fem.mesh.ungraded_clamp`).
    rtol, utol : float
        Newton tolerances: residual relative to the force scale, increment relative to L.
    max_iterations, max_cuts : int
        Newton iterations per step; halvings of a requested load step before giving up
        (the smallest sub-step is ``2**-max_cuts`` of it).
    progress : bool or callable, optional
        True shows a tqdm progress bar over the scales; a callable is called as
        ``progress(k, scale)`` after each requested scale converges.

    Returns
    -------
    FEMResult
        ``tip`` (n, 3) m, ``displacement(k)`` (dim, n_nodes) m, ``mesh``, ``export``,
        ``plot``.

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    coilrod.ConvergenceError
        A scale could not be reached; ``reached`` is the last converged scale and ``result``
        the :class:`FEMResult` of the requested scales before it (None if none).

    Notes
    -----
    Energy per reference volume (Zhao et al. 2019, seed eqs. 7-13)::

        W(F, x) = G/2 (J^(-2/3) tr(F^T F) - 3) + K/2 (J - 1)^2 - (F M) . B(x),  x = X + u

    with M(X) the reference magnetization,
    ``|M|(s) (cos theta_m cos psi_m, sin theta_m cos psi_m, sin psi_m)`` at s = X_1 (psi_m the
    elevation; ``|M| (cos theta_m, sin theta_m)`` in 2D).  First Piola stress
    ``P = dW_nH/dF - B (x) M``, body force ``G^T (F M)`` (G = grad B); the tangent includes
    the gradient terms of seed eq. (13) and the field's second derivatives ``field.hessian``
    for non-linear fields.  For a uniform field the
    magnetic load is dead and the tangent purely elastic.

    The load path is followed by the shared engine :mod:`coilrod.path` (tangent predictor,
    Newton with a backtracking line search, step cutting, stability checked at every step from
    the tangent's factorisation -- a change is located and reported, never jumped silently --
    and pseudo-arclength around folds); see :mod:`coilrod.fem.problem` for the convergence
    test.

    Examples
    --------
    >>> import coils, coilrod
    >>> rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(2e-3, 2e-3), coilrod.presets.M1())
    >>> B = rod.field_for_lambda(1.0)
    >>> res = solve_fem(rod, coils.UniformField((0, B, 0)), [1.0], dim=2, elements=(10, 1))
    >>> bool(0.25 < res.tip[0, 1] / rod.length < 0.35)   # about lambda/3 for small lambda
    True
    """
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    if not isinstance(field, Field):
        raise ValueError(f"field must be a coils Field; got {type(field).__name__}")
    scales = _scales(scales)
    nu = _checked_options(
        rod,
        field,
        dim,
        order,
        plane,
        formulation,
        poisson_ratio,
        rtol,
        utol,
        max_iterations,
        max_cuts,
    )
    asm = _assembler(rod, field, mesh, elements, dim, order, nu, plane, formulation)
    problem = FEMProblem(asm, rtol, utol)
    min_step = 2.0 ** -int(max_cuts)
    opts = PathOptions(
        newton=NewtonOptions(max_iter=int(max_iterations), backtracks=10, chord=FEMProblem.chord),
        min_step=min_step,
        bifurcation_tol=min(0.75, max(1e-4, 2.0 * min_step)),
    )
    progress, bar = _progress(progress, len(scales), dim)
    try:
        run = follow_load(
            problem, np.zeros(asm.size), scales, opts, name="solve_fem", progress=progress
        )
    except ConvergenceError as err:
        stats = problem.stats
        stats.steps, stats.cuts = err.steps, err.cuts
        err.result = _result(asm, err.points, stats) if err.points else None
        raise
    finally:
        if bar is not None:
            bar.close()
    stats = problem.stats
    stats.steps, stats.cuts = run.steps, run.cuts
    stats.iterations = [int(i) for i in run.iterations]
    result = _result(asm, run.points, stats)
    result.instabilities = [dict(e) for e in run.events]
    warn_events(run.events, "the FEM equilibrium path", stacklevel=3)
    return result


def _result(asm, points, stats) -> FEMResult:
    scales = np.array([p.scale for p in points])
    stable = np.array([p.stability > 0 for p in points], dtype=bool)
    error = np.array([p.error for p in points], dtype=float)
    return FEMResult(asm, scales, [p.u for p in points], stats, stable, error)
