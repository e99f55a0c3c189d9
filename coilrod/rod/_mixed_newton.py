"""Compiled Newton corrector of the planar rod's mixed layout in coaxial coils' fields (numba,
cached on disk).

One call runs :func:`coilrod.path.corrector.newton` to the end for a stack of states of
:class:`~coilrod.rod.planar.PlanarRod`'s mixed layout (positions, angles and force resultants
at every node) when the field is a sum of coaxial filament groups (a
:class:`~coils.CoilPair`, a coaxial :class:`~coils.CoilSystem`), uniform fields and constant
gradients (an ideal Maxwell pair, :class:`~coils.LinearField`): the field at the nodes (the
coils' compiled pass, called from here), the residual and band Jacobian
(:mod:`coilrod.rod._compiled`'s per-node kernels), the band LU and solves (the arithmetic of
``band_lu`` / ``band_solve``, member by member: the stacked Jacobian is block diagonal), the
step limit, the backtracking line search, the error and the stagnation test.

The batched corrector's bookkeeping is reproduced exactly: the members share the chord
decision (an iteration is a chord step when every active member's last error contraction is
at most ``opts.chord``), a fresh tangent is formed at the current states when a full Newton
step follows chord steps, the accepted trial's linearization becomes the tangent after a full
step, and the linearization returned is the engine's choice (``corrector._final``): the
tangent at the current states where it describes them all or where the tangent does not
cover every member (then all are linearized again), else the current residuals paired with
the last tangent (of each member's last fresh state, a chord step or less away).  Each
member's numbers do not depend on the others (the engine's stacked evaluations are block
diagonal), so the states, errors, iterations, residuals, factors, path rates and determinant
signs are those of the numpy path bit for bit when both run the same kernels
(``tests/test_rod_mixed_newton.py``; compiled against numpy, libm's sines against numpy's may
differ in the last bit).

For the 3D stability the kernel also counts the negative eigenvalues of the out-of-plane block
at the returned states (the model's own kernels: ``rc._odd_blocks_compiled`` and the block
LDL^T of :mod:`coilrod.rod._inertia`), which ``PlanarRod.negative_counts`` then reads.

Ski rental (README, "Cold start"): the engine's numpy corrector runs until its estimated cost
reaches :data:`COMPILE_AFTER` (about what compiling this kernel costs on a cold cache: 10-15 s
of CPU measured on the shared 2-core machine) or numba's cache holds it; the compiled one from
then on.  The test suite never compiles it (``tests/conftest.py``; tested through
``.py_func``).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numba as nb
import numpy as np

import coils._compiled as cc
import coils.coaxial as cx
from coils._immutable import kernel_input
from coils._numba_cache import Rental
from coils.field import FieldSum, ScaledField
from coils.ideal import LinearField, UniformField

from . import _compiled as rc
from . import _inertia as inertia
from .discrete import _EPS, _FLOOR
from .mesh import _remember

__all__ = ["COMPILE_AFTER", "compiled_pays", "charge", "coaxial_groups", "newton_mixed"]

#: Estimated CPU seconds of numpy Newton iterations of the mixed layout after which the
#: compiled corrector is used (ski rental); 0 compiles at the first call, ``math.inf`` never.
COMPILE_AFTER = 10.0
# measured cost of the numpy corrector (coil field, 16 segments): per call, per member iteration
_NUMPY_CALL_S, _NUMPY_ITER_S = 2e-4, 1.5e-4
_NV, _KL, _KU = 5, rc.KL, rc.KU
_D = _KL + _KU  # row of the diagonal in band storage
_ROWS = 2 * _KL + _KU + 1


def _digest() -> int:
    """A hash of the sources the kernel compiles in from other files (the rod's per-node
    kernels, the coils' pass): numba's cache checks only this file, so the kernel captures
    this number and its cache entry is replaced when one of them changes."""
    h = hashlib.sha256(cc._source_digest().to_bytes(8, "little"))
    try:
        for module in (rc, inertia):
            h.update(Path(module.__file__).read_bytes())
    except OSError:  # sources not shipped: numba cannot cache either
        return 0
    return int.from_bytes(h.digest()[:6], "little")


def compiled_pays() -> bool:
    """True if the compiled corrector should run: it is compiled (or in numba's cache), or the
    numpy corrector has cost :data:`COMPILE_AFTER` so far."""
    return _rental.pays()


def charge(iterations) -> None:
    """Charge the estimated cost (s of CPU) of a numpy corrector call of ``iterations`` (per
    member) to the ski rental."""
    _rental.charge(_NUMPY_CALL_S + _NUMPY_ITER_S * (float(np.sum(iterations)) + 1.0))


def coaxial_groups(field, factor: float = 1.0):
    """The parts of ``field`` with the factor each is scaled by, in the order in which the
    field's evaluation adds them (``FieldSum._add_to``, ``ScaledField._add_to``: the factors
    multiplied in the same order): coaxial filament groups, uniform fields and constant
    gradients (:class:`~coils.LinearField`, e.g. a Maxwell pair's ``ideal()``), or None if
    ``field`` has another part."""
    if isinstance(field, FieldSum):
        out = []
        for p in field.parts:
            sub = coaxial_groups(p, factor)
            if sub is None:
                return None
            out.extend(sub)
        return out
    if isinstance(field, ScaledField):
        return coaxial_groups(field.field, factor * field.factor)
    if isinstance(field, cx.CoaxialCoils) or type(field) in (UniformField, LinearField):
        return [(field, factor)]
    return None


def _field_arrays(groups):
    """The coils' kernel arguments of every coaxial group, concatenated (read-only, as the
    coils pass them: one compiled version of their kernel): per group its centre, axis,
    filament rows, winding rows, moments, first moment, parameters, with offsets into the
    concatenated rows; the uniform parts' B (u, 3) T; per part (kind 0 coaxial, 1 uniform;
    its index) and its factor."""
    coaxial = [g for g, _ in groups if not isinstance(g, LinearField)]
    args = [(g._kernel_args or g._prepare())[1] for g in coaxial]
    offs = np.zeros((len(args), 4), dtype=np.int64)  # filament, winding, moment offsets; n0
    fil, wind, beta = [np.zeros((0, 5))], [np.zeros((0, 4))], [np.zeros(0)]
    a = b = c = 0
    for i, (_center, _axis, f, wnd, bet, n0, _params) in enumerate(args):
        offs[i] = (a, b, c, n0)
        a, b, c = a + f.shape[0], b + wnd.shape[0], c + bet.shape[0]
        fil.append(f)
        wind.append(wnd)
        beta.append(bet)
    ends = np.array([a, b, c], dtype=np.int64)
    linear = [  # B0, origin, G (row-major) of the uniform and linear parts
        np.concatenate([g.B0, g.origin, g.G.ravel()])
        for g, _ in groups
        if isinstance(g, LinearField)
    ]
    order = np.zeros((len(groups), 2), dtype=np.int64)
    i = u = 0
    for row, (g, _) in enumerate(groups):
        if isinstance(g, LinearField):  # (1: uniform, 2: a constant gradient)
            order[row] = (1 if type(g) is UniformField else 2, u)
            u += 1
        else:
            order[row] = (0, i)
            i += 1
    return (
        kernel_input(np.array([x[0] for x in args]).reshape(-1, 3)),
        kernel_input(np.array([x[1] for x in args]).reshape(-1, 3)),
        kernel_input(np.concatenate(fil).reshape(-1, 5)),
        kernel_input(np.concatenate(wind).reshape(-1, 4)),
        kernel_input(np.concatenate(beta)),
        offs,
        ends,
        kernel_input(np.array([x[6] for x in args]).reshape(-1, 8)),
        np.array([f for _, f in groups], dtype=float),
        np.array(linear, dtype=float).reshape(-1, 15),
        order,
    )


#: :func:`_field_arrays` of the fields seen lately, by id (with the field: checked on a hit;
#: fields are immutable), at most ``mesh._CACHE_SIZE`` entries (``mesh._remember``).
_FIELDS: dict = {}


def _fields_of(field):
    """:func:`_field_arrays` of ``field``'s coaxial groups (remembered), or None if it is not
    made of coaxial groups only."""
    hit = _FIELDS.get(id(field))
    if hit is not None and hit[0] is field:
        return hit[1]
    groups = coaxial_groups(field)
    arrays = None if not groups else _field_arrays(groups)
    _remember(_FIELDS, id(field), (field, arrays))
    return arrays


def _constants(p):
    """The problem's arrays and numbers the kernel reads (cached on it), or None where the
    field is not made of coaxial groups."""
    cached = p.__dict__.get("_mixed_newton_constants", False)
    if cached is not False:
        return cached
    fields = _fields_of(p.field)
    out = None
    if fields is not None:
        mesh = (p.mu, p.mesh.h, p.mesh.w, p._inv_w, p._inv_h, p._bend_scale, p.clamp)
        arrays = tuple(np.ascontiguousarray(x, dtype=float) for x in mesh)
        par = np.array([p.L, p.theta0, p.tol, _floor(), float(p.max_rotation)])
        out = (arrays, par, fields)
    p._mixed_newton_constants = out
    return out


def _floor() -> float:
    """The error's round-off floor factor (``discrete._FLOOR`` eps)."""
    return _FLOOR * _EPS


def newton_mixed(problem, U, S, opts, tangent: bool = True):
    """Newton's method for the stack ``U`` (k, 5 n) (float, C order: iterated in place) at
    scales ``S`` (k,) of a mixed-layout :class:`~coilrod.rod.planar.PlanarRod` in coaxial
    coils' field, with :class:`~coilrod.path.corrector.NewtonOptions` ``opts``.

    Returns None where it does not apply (another field; a point the coils cannot evaluate:
    ``U`` is then as given and the numpy corrector reports it), else a dict of arrays:
    ``U`` (k, 5n) the last iterates, ``R``, ``R1`` (k, 5n) the residual and dR/dscale there,
    ``M`` (k, 7) per member the error (inf where inadmissible), the iterations, 1 where the
    residual is finite, the sign of det J of the returned tangent (0 where singular), 1 where
    that tangent is bad (not finite or singular), 1 where the field's hessian at ``U`` is in
    ``H``, and (with ``tangent`` and an out-of-plane block) the out-of-plane negative
    eigenvalues (``OutOfPlane.odd_count``, -1 where not finite); with ``tangent`` also
    ``B`` (k n, 3), ``G`` (k n, 9), ``H`` (k n, 27) the field at
    the nodes, ``ab`` (16, 5 n k) the factorised band of the returned tangent (Fortran order,
    ``RodTangent``'s layout), ``ipiv`` (5 n k,) its row interchanges, ``RT1`` (k, 5n) its
    load derivative and ``rate`` (k, 5n) the path rate ``-J^-1 R1`` (NaN rows where bad).
    """
    const = _constants(problem)
    if const is None:
        return None
    arrays, par, fields = const
    k, size = U.shape
    n = size // _NV
    oop = problem.out_of_plane
    k1, k2 = (float(oop.stiffness[0]), float(oop.stiffness[1])) if oop is not None else (1.0, 1.0)
    linear = 1.0 if problem.linear else 0.0
    fpar = np.array([*par, float(problem.full_step_growth), float(opts.chord), k1, k2, linear])
    chords = opts.chord > 0 and not problem.cheap_tangent
    ipar = np.array(
        [
            opts.max_iter,
            opts.backtracks,
            opts.stagnation,
            chords,
            opts.chord_start,
            tangent,
            problem.out_of_plane is not None,
        ],
        dtype=np.int64,
    )
    start = U.copy()
    pts = np.empty((n, 3))
    pts_ro = pts.view()
    pts_ro.flags.writeable = False
    # (every entry is written by the kernel before it is read)
    out = {
        "U": U,
        "R": np.empty((k, size)),
        "R1": np.empty((k, size)),
        "B": np.empty((k * n, 3)),
        "G": np.empty((k * n, 9)),
        "H": np.empty((k * n, 27)),
        "ab": np.empty((_ROWS, size * k), order="F"),
        "ipiv": np.empty(size * k, dtype=np.int64),
        "RT1": np.empty((k, size)),
        "rate": np.empty((k, size)),
        "M": np.zeros((k, 7)),
    }
    trial = np.empty((_ROWS, size * k), order="F")
    code = _newton(
        U, np.ascontiguousarray(S, dtype=float), *arrays, fpar, ipar, fields, pts, pts_ro,
        out["R"], out["R1"], out["B"], out["G"], out["H"], out["ab"], out["ipiv"], out["RT1"],
        out["rate"], out["M"], trial,
    )  # fmt: skip
    if code != 0:  # a point the coils cannot evaluate: the numpy path reports it
        U[:] = start
        return None
    return out


def _make_kernel(digest: int):
    """The compiled corrector (see :func:`newton_mixed`), its cache entry tied to ``digest``
    (:func:`_digest`)."""

    @nb.njit(cache=True, error_model="numpy")
    def newton_kernel(
        U, S, mu, h, w, inv_w, inv_h, bend_scale, clamp, fpar, ipar, fa, pts, pts_ro,
        R, R1, B, G, H, ab, ipiv, RT1, rate, M, tab,
    ):  # fmt: skip
        """The corrector: U in place, the outputs of :func:`newton_mixed` filled; returns 0,
        or 1 if the coils could not evaluate a point (the outputs are then not valid)."""
        if digest == -1:  # never true: ties the cache entry to the sources (_digest)
            return -1
        k, size = U.shape
        n = size // 5
        yes = ipar[0] >= 0  # (True, typed as any bool: one compiled version of _linearize)
        model = (mu, h, w, clamp, fpar, fa, pts, pts_ro, np.empty((14, n)))
        cur = (U, R, R1, B, G, G.reshape((k * n, 3, 3)), H, H.reshape((k * n, 3, 3, 3)), ab)
        trial = _trial_arrays(k, n, tab)
        Ut, Rt = trial[0], trial[1]
        book, marks = _bookkeeping(k, ipar[4] != 0 and ipar[3] != 0)
        err, alive, moved, fresh = book[0], book[1], book[5], marks[0]
        e1 = np.empty(1)
        DU = np.empty((k, size))
        for j in range(k):  # the start, with its tangent
            st = _linearize_into(cur, j, S[j], yes, model)
            if st == 2:
                return 1
            _new_tangent(j, st, RT1, R1, marks)
            err[j] = _error(R, U, j, inv_w, inv_h, bend_scale, fpar, st == 0, e1)
            alive[j] = err[j] < math.inf
        owners_all = True  # the tangent covers every member
        for _ in range(ipar[0]):
            n_act, worst, stale = _active(book, fresh)
            if n_act == 0:
                break
            chord = ipar[3] != 0 and worst <= fpar[6]
            if not chord and stale:  # a new tangent at the current states
                for j in range(k):  # (a fresh member's is its tangent's: the same numbers)
                    if alive[j] and err[j] > 1.0 and not fresh[j]:
                        st = _linearize_into(cur, j, S[j], yes, model)
                        if st == 2:
                            return 1
                        _new_tangent(j, st, RT1, R1, marks)
                owners_all = n_act == k
            if _newton_steps(U, R, ab, ipiv, DU, book, marks) == 0:
                break
            n_moved = 0
            for j in range(k):  # the line searches along the steps
                if not moved[j]:
                    continue
                alpha = full = _step_limit(j, DU, fpar[4], moved)
                for _r in range(ipar[1] + 1):
                    _trial_state(j, alpha, U, DU, Ut)
                    st = _linearize_into(trial, j, S[j], not chord, model)
                    if st == 2:
                        return 1
                    e_new = _error(Rt, Ut, j, inv_w, inv_h, bend_scale, fpar, st == 0, e1)
                    if _accepted(j, e_new, alpha == full, st, chord, fpar[5], cur, trial, RT1,
                                 book, marks):  # fmt: skip
                        n_moved += 1
                        break
                    alpha = 0.5 * alpha
                _stopped(j, book)
            if not chord and n_moved > 0:
                owners_all = n_moved == k
            _stagnation(book, ipar[2])
        want_tangent, want_3d, linear = ipar[5] != 0, ipar[6] != 0, fpar[9] != 0.0
        all_fresh = fresh.all()
        if want_tangent and not owners_all:  # the engine linearizes every member again
            for j in range(k):
                if not fresh[j]:  # (a fresh member's tangent is at its state: the same)
                    st = _linearize_into(cur, j, S[j], yes, model)
                    if st == 2:
                        return 1
                    _new_tangent(j, st, RT1, R1, marks)
        # (else the engine's residuals have no hessian; a linear field has none)
        keep_h = (not owners_all or all_fresh) and not linear
        if want_tangent and want_3d and not linear and not keep_h:  # the 3D count's hessian
            for j in range(k):
                if not _hessian(U, j, fpar, clamp, fa, pts, pts_ro, B, G, H):
                    return 1
                marks[2][j] = True
            keep_h = True
        for j in range(k):
            _report(j, keep_h, book, marks, M)
            if want_tangent:
                _rate_and_sign(j, ab, ipiv, R1, rate, M, marks)
        if want_tangent and want_3d:  # the out-of-plane count of the 3D stability
            _odd_counts(U, S, mu, h, w, inv_h, fpar, B, G, H, M)
        return 0

    return newton_kernel


#: The kernel's steps: inlined into it in numba's IR (compiled with it as one function: each
#: compiled apart would add its own optimisation and machine code to the kernel's cold compile)
_step = nb.njit(inline="always", error_model="numpy")

# The kernel passes its arrays to its steps in tuples:
#   model = (mu, h, w, clamp, fpar, fa, pts, pts_ro, T): the problem and the per-node scratch
#   cur / trial = (U, R, R1, B, G, G3, H, H4, ab): states, residuals, dR/dscale, the field at
#       the nodes (G3, H4: G, H as (k n, 3, 3[, 3]) views) and the band of the current states
#       (the tangent) / of the line search's trial states
#   book = (err, alive, iters, slow, ratio, moved): per member its error, whether it still
#       iterates, its iterations, its slow contractions in a row, its last error contraction,
#       whether it moved in this iteration
#   marks = (fresh, cur_ok, has_h, t_ok, t_lu, t_bad): per member whether its current state
#       is its tangent's, its current residual is finite, H holds the hessian at its current
#       state, its tangent's state was finite, its tangent is factorised, ... with an exactly
#       zero pivot


@_step
def _bookkeeping(k, chord_start):
    """``book`` and ``marks`` (above) at the start of k members (``chord_start``: their
    first iteration may be a chord step)."""
    book = (
        np.empty(k),
        np.zeros(k, dtype=np.bool_),
        np.zeros(k, dtype=np.int64),
        np.zeros(k, dtype=np.int64),
        np.full(k, 0.0 if chord_start else 1.0),
        np.zeros(k, dtype=np.bool_),
    )
    marks = (
        np.ones(k, dtype=np.bool_),
        np.zeros(k, dtype=np.bool_),
        np.ones(k, dtype=np.bool_),
        np.zeros(k, dtype=np.bool_),
        np.zeros(k, dtype=np.bool_),
        np.zeros(k, dtype=np.bool_),
    )
    return book, marks


@_step
def _trial_arrays(k, n, tab):
    """``trial`` (above): the line search's arrays for k members of n nodes, its band
    ``tab``."""
    Gt = np.zeros((k * n, 9))
    Ht = np.zeros((k * n, 27))
    return (
        np.empty((k, 5 * n)),
        np.empty((k, 5 * n)),
        np.empty((k, 5 * n)),
        np.zeros((k * n, 3)),
        Gt,
        Gt.reshape((k * n, 3, 3)),
        Ht,
        Ht.reshape((k * n, 3, 3, 3)),
        tab,
    )


@_step
def _linearize_into(arrays, j, s, tangent, model):
    """:func:`_linearize` of member j of ``arrays`` (``cur`` or ``trial``) at scale s."""
    U, R, R1, B, G, G3, H, H4, ab = arrays
    mu, h, w, clamp, fpar, fa, pts, pts_ro, T = model
    return _linearize(
        U, j, s, tangent, mu, h, w, clamp, fpar, fa, pts, pts_ro, R, R1, B, G, G3, H, H4, ab, T
    )


@_step
def _new_tangent(j, st, RT1, R1, marks):
    """Member j's current state was linearized with its tangent (:func:`_linearize`'s code
    ``st``): the marks, and the tangent's load derivative."""
    fresh, cur_ok, has_h, t_ok, t_lu, _t_bad = marks
    cur_ok[j] = t_ok[j] = st == 0
    t_lu[j] = False
    fresh[j] = True
    has_h[j] = True
    _copy_row(RT1, R1, j)


@_step
def _active(book, fresh):
    """The members that still iterate (alive, error above 1): their number, their largest
    last error contraction, and whether one's tangent is not at its current state."""
    err, alive, _iters, _slow, ratio, _moved = book
    n_act = 0
    worst = 0.0
    stale = False
    for j in range(err.shape[0]):
        if alive[j] and err[j] > 1.0:
            n_act += 1
            worst = max(worst, ratio[j])
            if not fresh[j]:
                stale = True
    return n_act, worst, stale


@_step
def _newton_steps(U, R, ab, ipiv, DU, book, marks):
    """The Newton step ``-J^-1 R`` of every member that still iterates into its row of DU,
    with its tangent (factorised here once); a member without a finite step stops.  Marks
    the members with a step as moved; returns their number."""
    err, alive, _iters, _slow, _ratio, moved = book
    _fresh, _cur_ok, _has_h, t_ok, t_lu, t_bad = marks
    k, size = U.shape
    rhs = np.empty(size)
    n_step = 0
    for j in range(k):
        moved[j] = False
        if not (alive[j] and err[j] > 1.0):
            continue
        _factor(ab, ipiv, j, size, t_ok, t_lu, t_bad)
        ok = t_ok[j] and not t_bad[j]
        if ok:
            for q in range(size):
                rhs[q] = -R[j, q]
            _band_solve(ab, ipiv, j * size, size, rhs)
            for q in range(size):
                DU[j, q] = rhs[q]
                if not math.isfinite(rhs[q]):
                    ok = False
        if not ok:
            alive[j] = False
            continue
        moved[j] = True  # (for now: has a step)
        n_step += 1
    return n_step


@_step
def _step_limit(j, DU, max_rotation, moved):
    """Member j's first step length: 1, or less where its step turns a node by more than
    ``max_rotation``; it has not moved yet."""
    moved[j] = False
    rot = 0.0
    for i in range(DU.shape[1] // 5):
        a = abs(DU[j, 5 * i + 2])
        if a > rot:
            rot = a
    return min(1.0, max_rotation / rot) if rot > 0 else 1.0


@_step
def _trial_state(j, alpha, U, DU, Ut):
    """Member j's trial state ``U + alpha DU``."""
    for q in range(U.shape[1]):
        Ut[j, q] = U[j, q] + alpha * DU[j, q]


@_step
def _accepted(j, e_new, full, st, chord, growth, cur, trial, RT1, book, marks):
    """Whether member j's trial (error ``e_new``; ``full``: at its first step length) is
    accepted -- its error falls or is at most 1, or at the first length it grows by at
    most ``growth`` -- and then the trial becomes its current state (after a full step
    with its tangent)."""
    err, _alive, iters, slow, ratio, moved = book
    fresh, cur_ok, has_h, t_ok, t_lu, _t_bad = marks
    U, R, R1, B, G, _G3, H, _H4, ab = cur
    Ut, Rt, R1t, Bt, Gt, _Gt3, Ht, _Ht4, tab = trial
    e_old = err[j]
    accept = e_new < e_old or e_new <= 1.0
    if not accept:
        accept = full and e_new <= growth * e_old and e_new < math.inf
    if not accept:
        return False
    slow[j] = slow[j] + 1 if e_new > 0.5 * e_old else 0
    ratio[j] = e_new / e_old if e_old > 0 else 0.0
    _accept(j, not chord, U, Ut, R, Rt, R1, R1t, B, Bt, G, Gt, H, Ht, ab, tab)
    err[j] = e_new
    iters[j] += 1
    cur_ok[j] = st == 0
    has_h[j] = not chord
    fresh[j] = False
    if not chord:  # the trial's linearization carries its tangent
        _copy_row(RT1, R1, j)
        t_ok[j] = st == 0
        t_lu[j] = False
        fresh[j] = True
    moved[j] = True
    return True


@_step
def _stopped(j, book):
    """Member j stops where its line search failed (the failed search counts)."""
    if not book[5][j]:
        book[1][j] = False
        book[2][j] += 1


@_step
def _stagnation(book, stagnation):
    """The members that moved stop after ``stagnation`` slow contractions in a row (error
    still above 1)."""
    err, alive, _iters, slow, _ratio, moved = book
    for j in range(err.shape[0]):
        if moved[j] and slow[j] >= stagnation and err[j] > 1.0:
            alive[j] = False


@_step
def _report(j, keep_h, book, marks, M):
    """Member j's error, iterations, finite residual and hessian flags into its row of M
    (``keep_h``: H holds the hessian where ``has_h`` says so)."""
    M[j, 0] = book[0][j]
    M[j, 1] = book[2][j]
    M[j, 2] = 1.0 if marks[1][j] else 0.0
    M[j, 5] = 1.0 if (keep_h and marks[2][j]) else 0.0


@_step
def _rate_and_sign(j, ab, ipiv, R1, rate, M, marks):
    """Member j's returned tangent factorised, its badness, its path rate ``-J^-1 R1`` (NaN
    where bad) and the sign of its determinant into M."""
    _fresh, _cur_ok, _has_h, t_ok, t_lu, t_bad = marks
    size = R1.shape[1]
    _factor(ab, ipiv, j, size, t_ok, t_lu, t_bad)
    bad = not t_ok[j] or t_bad[j]
    M[j, 4] = 1.0 if bad else 0.0
    if bad:
        for q in range(size):
            rate[j, q] = math.nan
        return
    rhs = np.empty(size)
    for q in range(size):
        rhs[q] = R1[j, q]
    _band_solve(ab, ipiv, j * size, size, rhs)
    odd = 0
    for q in range(size):
        rate[j, q] = -rhs[q]
        c = j * size + q
        if ab[_D, c] < 0.0:
            odd += 1
        if ipiv[c] != c:
            odd += 1
    M[j, 3] = 1.0 if odd % 2 == 0 else -1.0


@nb.njit(cache=True, error_model="numpy")
def _linearize(
    U, j, s, tangent, mu, h, w, clamp, fpar, fa, pts, pts_ro, R, R1, B, G, G3, H, H4, ab, T
):
    """``PlanarRod.linearize`` of member j of the stack U (``_mixed``: the field at its nodes,
    then the per-node kernels of :mod:`coilrod.rod._compiled`), into row j of R, R1, its
    nodes' rows of B, G, H and (``tangent``) its columns of the band ``ab``.  Returns 0, 1 if
    the residual is not finite (its row then NaN), 2 if the coils could not evaluate a
    point."""
    n = pts.shape[0]
    size = 5 * n
    L = fpar[0]
    finite = _points(U, j, L, clamp, pts)
    hess = tangent and fpar[9] == 0.0  # (a linear field has no hessian: the engine's H None)
    p0 = j * n
    for p in range(p0, p0 + n):
        for c in range(3):
            B[p, c] = 0.0
        for c in range(9):
            G[p, c] = 0.0
        if hess:
            for c in range(27):
                H[p, c] = 0.0
    if finite:
        bad = _coil_fields(
            pts_ro, np.int64(7) if hess else np.int64(3), fa, B[p0 : p0 + n], G[p0 : p0 + n],
            H[p0 : p0 + n] if hess else H[0:0],
        )  # fmt: skip
        if bad:
            return 2
    else:  # (the engine's validated path: NaN for this member)
        for p in range(p0, p0 + n):
            for c in range(3):
                B[p, c] = math.nan
            for c in range(9):
                G[p, c] = math.nan
            if hess:
                for c in range(27):
                    H[p, c] = math.nan
    ok = rc._node_terms(U, B, G3, H4, hess, L, mu, j, T)
    ok = rc._residual(U, s, j, T, h, w, fpar[1], R, R1) and ok
    if tangent:
        c0 = j * size
        for c in range(c0, c0 + size):
            for r in range(ab.shape[0]):
                ab[r, c] = 0.0
        rc._tangent(U, s, j, T, h, w, ab)
    if not ok:
        for q in range(size):
            R[j, q] = math.nan
        return 1
    return 0


@nb.njit(cache=True, error_model="numpy")
def _copy_row(dst, src, j):
    """Row j of src into row j of dst."""
    for q in range(src.shape[1]):
        dst[j, q] = src[j, q]


@nb.njit(cache=True, error_model="numpy")
def _accept(j, tangent, U, Ut, R, Rt, R1, R1t, B, Bt, G, Gt, H, Ht, ab, tab):
    """Member j's trial state, residual, load derivative and field at its nodes (with
    ``tangent``: the hessian and its band columns too) become its current ones."""
    size = U.shape[1]
    n = size // 5
    for dst, src in ((U, Ut), (R, Rt), (R1, R1t)):
        _copy_row(dst, src, j)
    for p in range(j * n, (j + 1) * n):
        for c in range(3):
            B[p, c] = Bt[p, c]
        for c in range(9):
            G[p, c] = Gt[p, c]
        if tangent:
            for c in range(27):
                H[p, c] = Ht[p, c]
    if tangent:
        for c in range(j * size, (j + 1) * size):
            for r in range(ab.shape[0]):
                ab[r, c] = tab[r, c]


@nb.njit(cache=True, error_model="numpy")
def _odd_counts(U, S, mu, h, w, inv_h, fpar, B, G, H, M):
    """Negative eigenvalues of the out-of-plane block of the 3D second variation at each
    member's state into ``M[:, 6]`` (``OutOfPlane.odd_count`` of the mixed layout: its blocks
    by ``rc._odd_blocks_compiled``, their inertia by ``_inertia._inertia``, member by member;
    -1 where not finite)."""
    k = U.shape[0]
    n = w.shape[0]
    nf = n - 1
    D = np.zeros((1, nf, 4, 4))
    E = np.zeros((1, max(nf - 1, 1), 4, 4))
    neg = np.zeros(1, dtype=np.int64)
    zero = np.zeros(1, dtype=np.int64)
    has_h = fpar[9] == 0.0  # (not a linear field)
    for j in range(k):
        D[:] = 0.0
        E[:] = 0.0
        p0 = j * n
        rc._odd_blocks_compiled(
            U[j : j + 1], S[j : j + 1], mu, h, w, inv_h, fpar[7], fpar[8], fpar[0],
            B[p0 : p0 + n], G[p0 : p0 + n], H[p0 : p0 + n], has_h, D, E,
        )  # fmt: skip
        neg[0] = 0
        zero[0] = 0
        inertia._inertia(D, E, neg, zero, np.float64(1e-13))
        M[j, 6] = neg[0] - nf if neg[0] >= 0 else neg[0]


@nb.njit(cache=True, error_model="numpy")
def _points(U, j, L, clamp, pts):
    """The nodes of member j as points (n, 3), m (as ``PlanarRod._field`` makes them); False
    if one is not finite."""
    finite = True
    for i in range(pts.shape[0]):
        pts[i, 0] = U[j, 5 * i] * L + clamp[0]
        pts[i, 1] = U[j, 5 * i + 1] * L + clamp[1]
        pts[i, 2] = clamp[2]
        for c in range(3):
            if not math.isfinite(pts[i, c]):
                finite = False
    return finite


@nb.njit(cache=True, error_model="numpy")
def _hessian(U, j, fpar, clamp, fa, pts, pts_ro, B, G, H):
    """The coils' hessian pass alone at the nodes of member j into its rows of H (NaN where a
    node is not finite; ``OutOfPlane._mixed_fields``: the combined pass's numbers); False if
    the coils could not evaluate a point."""
    n = pts.shape[0]
    p0 = j * n
    finite = _points(U, j, fpar[0], clamp, pts)
    for p in range(p0, p0 + n):
        for c in range(27):
            H[p, c] = 0.0 if finite else math.nan
    if not finite:
        return True
    return not _coil_fields(
        pts_ro, np.int64(4), fa,
        B[0:0], G[0:0], H[p0 : p0 + n],
    )  # fmt: skip


@nb.njit(cache=True, error_model="numpy")
def _coil_fields(pts, flags, fa, B, G, H):
    """Add every part's field at the points to B (n, 3), G (n, 9) and H (n, 27) as ``flags``
    asks (1: B, 2: G, 4: H), in order (as the field's evaluation does: a uniform part adds its
    factor times its B); True if a coaxial group reports a point it cannot evaluate."""
    centers, axes, fil, wind, beta, offs, ends, gpar, factors, ub, order = fa
    ng = centers.shape[0]
    for part in range(order.shape[0]):
        f = factors[part]
        kind = order[part, 0]
        if kind == 1:  # uniform: B only (Field._add_to)
            if flags & 1:
                u = order[part, 1]
                for p in range(B.shape[0]):
                    for c in range(3):
                        B[p, c] += f * ub[u, c]
            continue
        if kind == 2:  # a constant gradient: B0 + (x - origin) G^T, G (LinearField)
            u = order[part, 1]
            for p in range(pts.shape[0]):
                if flags & 1:
                    d0 = pts[p, 0] - ub[u, 3]
                    d1 = pts[p, 1] - ub[u, 4]
                    d2 = pts[p, 2] - ub[u, 5]
                    for c in range(3):
                        b = ub[u, c] + (
                            d0 * ub[u, 6 + 3 * c] + d1 * ub[u, 7 + 3 * c] + d2 * ub[u, 8 + 3 * c]
                        )
                        B[p, c] += f * b
                if flags & 2:
                    for c in range(9):
                        G[p, c] += f * ub[u, 6 + c]
            continue
        g = order[part, 1]
        a0, w0, b0 = offs[g, 0], offs[g, 1], offs[g, 2]
        a1 = offs[g + 1, 0] if g + 1 < ng else ends[0]
        w1 = offs[g + 1, 1] if g + 1 < ng else ends[1]
        b1 = offs[g + 1, 2] if g + 1 < ng else ends[2]
        err = np.empty(3 + w1 - w0, dtype=np.int64)
        bad = cc.coaxial_field(
            pts, centers[g], axes[g], fil[a0:a1], wind[w0:w1], beta[b0:b1], offs[g, 3],
            gpar[g], flags, f, B, G, H, err,
        )  # fmt: skip
        if bad:
            return True
    return False


@nb.njit(cache=True, error_model="numpy")
def _error(R, U, j, inv_w, inv_h, bend_scale, fpar, ok, e1):
    """``PlanarRod.error`` of member j, inf where not ``ok`` or not finite (``_errors``)."""
    if not ok:
        return math.inf
    rc.mixed_error(R[j : j + 1], U[j : j + 1], inv_w, inv_h, bend_scale, fpar[2], fpar[3], e1)
    e = e1[0]
    return e if math.isfinite(e) else math.inf


@nb.njit(cache=True, error_model="numpy")
def _factor(ab, ipiv, j, size, t_ok, t_lu, t_bad):
    """Factorise member j's tangent in place once (``RodTangent._factor_band``: an
    inadmissible member's block is the identity first)."""
    if t_lu[j]:
        return
    c0 = j * size
    if not t_ok[j]:
        for c in range(c0, c0 + size):
            for r in range(ab.shape[0]):
                ab[r, c] = 0.0
            ab[_D, c] = 1.0
    t_bad[j] = _band_lu(ab, c0, size, ipiv) > 0
    t_lu[j] = True


@nb.njit(cache=True, error_model="numpy")
def _band_lu(ab, c0, n, ipiv):
    """``rc.band_lu`` (kl = ku = 5, threshold pivoting) of the n columns from c0 of a stacked
    band (a block of its block diagonal), the same arithmetic; ``ipiv`` of the stacked
    matrix (global row indices)."""
    kl = _KL
    ku = _KU
    kv = ku + kl
    info = 0
    ju = 0
    for jl in range(n):
        j = c0 + jl
        km = min(kl, n - 1 - jl)
        jp = 0
        diag = abs(ab[kv, j])
        big = diag
        for i in range(1, km + 1):
            a = abs(ab[kv + i, j])
            if a > big:
                big = a
                jp = i
        if diag >= rc.PIVOT_THRESHOLD * big:
            jp = 0
        ipiv[j] = j + jp
        if ab[kv + jp, j] == 0.0:
            if info == 0:
                info = jl + 1
            continue
        ju = max(ju, min(jl + ku + jp, n - 1))
        if jp != 0:
            for cl in range(jl, ju + 1):
                c = c0 + cl
                r1 = kv + j + jp - c
                r0 = kv + j - c
                tmp = ab[r1, c]
                ab[r1, c] = ab[r0, c]
                ab[r0, c] = tmp
        piv = ab[kv, j]
        for i in range(1, km + 1):
            ab[kv + i, j] /= piv
        for cl in range(jl + 1, ju + 1):
            c = c0 + cl
            u = ab[kv + j - c, c]
            if u != 0.0:
                for i in range(1, km + 1):
                    ab[kv + i + j - c, c] -= ab[kv + i, j] * u
    return info


@nb.njit(cache=True, error_model="numpy")
def _band_solve(ab, ipiv, c0, n, b):
    """``rc.band_solve`` of one right-hand side b (n,) with the block of the stacked factors
    at columns c0 .. c0 + n (the same arithmetic); b is overwritten by x."""
    kv = _KU + _KL
    for jl in range(n - 1):  # L, with the row interchanges as they were made
        j = c0 + jl
        lm = min(_KL, n - 1 - jl)
        p = ipiv[j] - c0
        if p != jl:
            tmp = b[p]
            b[p] = b[jl]
            b[jl] = tmp
        for i in range(1, lm + 1):
            f = ab[kv + i, j]
            if f != 0.0:
                b[jl + i] -= f * b[jl]
    for jl in range(n - 1, -1, -1):  # U, bandwidth kl + ku
        j = c0 + jl
        d = ab[kv, j]
        b[jl] /= d
        for il in range(max(0, jl - kv), jl):
            f = ab[kv + il - jl, j]
            if f != 0.0:
                b[il] -= f * b[jl]


_newton = _make_kernel(_digest())
#: The ski rental of the compiled corrector (:class:`coils._numba_cache.Rental`).
_rental = Rental(__name__, lambda: _newton)
