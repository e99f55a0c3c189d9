"""The planar rod's mixed layout (non-uniform fields) on its fast paths against the general ones:
the field's prepared evaluator (:meth:`coils.field.Field.evaluator`, bound once per problem)
gives the numbers and errors of the validated public methods, bit for bit.  Nothing here
compiles: the coaxial kernel is replaced by a recording stand-in or runs as the ski rental's
numpy pass."""

from __future__ import annotations

import numpy as np
import pytest

import coils
import coils.coaxial as cx
from coilrod import presets
from coilrod.rod.discrete import DiscreteRod
from coilrod.rod.mesh import RodMesh
from coilrod.rod.solve import build_problem, make_mesh


@pytest.fixture
def numpy_pass(monkeypatch):
    """The coaxial coils' numpy pass (the ski rental before compiling), whatever the process
    has compiled."""
    monkeypatch.setattr(cx._rental, "ready", False)
    monkeypatch.setattr(cx, "COMPILE_AFTER", np.inf)
    monkeypatch.setattr(cx._rental, "held", lambda: False)


def _points(pair, n=7):
    rng = np.random.default_rng(3)
    pts = pair.center + 0.3 * pair.filaments[0, 1] * rng.normal(size=(n, 3))
    pts[0] = pair.center  # on the axis
    return np.ascontiguousarray(pts)


def test_coaxial_evaluator_is_the_public_methods(numpy_pass, monkeypatch):
    pair = coils.MaxwellPair(radius=0.05, turns=100, current=2.0, axis=(0.0, 0.6, 0.8))
    pts = _points(pair)
    fields = pair.evaluator()
    B, G, H = fields(pts.copy(), True)
    refs = pair.B_gradient_hessian(pts)
    for got, ref in zip((B, G, H), refs, strict=True):
        assert got.shape == ref.shape
        assert np.array_equal(got, ref)
    B2, G2, none = fields(pts.copy(), False)
    B_ref, G_ref = pair.B_and_gradient(pts)
    assert none is None
    assert np.array_equal(B2, B_ref)
    assert np.array_equal(G2, G_ref)
    # a point on the winding: the public methods' ValueError
    on_wire = pts.copy()
    on_wire[2] = (
        pair.center + pair.filaments[1, 0] * pair.axis + pair.filaments[1, 1] * pair.rotation[:, 0]
    )
    with pytest.raises(ValueError, match="winding") as public:
        pair.B_gradient_hessian(on_wire)
    with pytest.raises(ValueError, match="winding") as fast:
        fields(on_wire.copy(), True)
    assert str(fast.value) == str(public.value)

    # compiled: the kernel called directly with the arguments the public path gives it (a
    # recording stand-in for the compiled pass: nothing compiles)
    calls = []

    def kernel(p, *rest):
        *args, flags, factor, B_, G_, H_, err = rest
        calls.append((p.copy(), p.flags.writeable, args, flags, factor, B_.shape, G_.shape))
        B_ += p.sum(axis=1)[:, None]
        G_ += 2.0 * p[:, :1]
        if flags & 4:
            H_ += 3.0 * p[:, 1:2]
        return False

    _, args, n_err = pair._kernel_args
    fake = pair.replace()  # (a fresh object: its own kernel-argument cache)
    fake._set_cache("_kernel_args", (kernel, args, n_err))
    monkeypatch.setattr(cx._rental, "ready", True)
    for hessian in (True, False):
        public = fake.B_gradient_hessian(pts) if hessian else (*fake.B_and_gradient(pts), None)
        got = fake.evaluator()(pts.copy(), hessian)
        for a, b in zip(got, public, strict=True):
            assert (a is None and b is None) or np.array_equal(a, b)
        (p1, w1, a1, f1, s1, *sh1), (p2, w2, a2, f2, s2, *sh2) = calls[-2:]
        assert np.array_equal(p1, p2)
        assert not w1
        assert not w2
        assert all(x is y for x, y in zip(a1, a2, strict=True))
        assert (f1, s1, sh1) == (f2, s2, sh2)


def test_planar_field_through_the_evaluator_is_bitwise_the_validated_path(numpy_pass):
    rod = presets.seed_rod()
    pair = coils.HelmholtzPair(radius=2 * rod.length, turns=200, current=1.0, axis="y")
    problem = build_problem(rod, pair, make_mesh(rod, 6), np.zeros(3), 0.3)
    rng = np.random.default_rng(1)
    x = 0.4 * rng.normal(size=(3, problem.n, 2))
    for hessian in (True, False):
        got = problem._field(x, hessian)
        ref = DiscreteRod._field(problem, x, hessian)
        for a, b in zip(got, ref, strict=True):
            assert (a is None and b is None) or np.array_equal(a, b)
    # the 3D count's hessian where a linearization has none (a chord step's): the coils'
    # hessian pass alone, bitwise the combined pass's
    oop = problem.with_out_of_plane((0.77, 1.3, 1.0)).out_of_plane
    U = problem.straight() + 0.05 * rng.normal(size=(3, problem.size))
    lin = problem.linearize(U, np.full(3, 1e5), tangent=False)
    assert lin.field_hessian is None
    got = oop._mixed_fields(lin, 3)
    ref = DiscreteRod._field_by_member(problem, U.reshape(3, problem.n, 5)[:, :, 0:2], True)
    for a, b in zip(got, ref, strict=True):
        assert np.array_equal(a.reshape(b.shape), b)
    # a member that is not finite: the validated path's error, and NaN for that member only
    H = problem._hessian_by_member(np.where(np.arange(3)[:, None, None] == 1, np.nan, x))
    assert np.isnan(H.reshape(3, -1)[1]).all()
    assert np.isfinite(H.reshape(3, -1)[[0, 2]]).all()
    x[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        problem._field(x, True)
    B, _, _ = problem._field_by_member(x, True)
    B = B.reshape(3, problem.n, 3)
    assert np.isnan(B[1]).all()
    assert np.isfinite(B[[0, 2]]).all()


def test_compiled_out_of_plane_blocks_are_the_numpy_assembly(numpy_pass, monkeypatch):
    # the mixed layout's out-of-plane blocks assembled by the kernel (run as Python through
    # its .py_func: nothing compiles) against the numpy assembly, at off-equilibrium states
    # (moment residuals and forces nonzero) in a coil field (hessian terms) and a linear one;
    # then the ski rental's switch: the 3D counts the same either way
    import coilrod.rod._compiled as rc

    rod = presets.seed_rod()
    L = rod.length
    pair = coils.MaxwellPair(radius=2 * L, turns=200, current=1.0, axis="y", center=(L, 0, 0))
    rng = np.random.default_rng(2)
    python_kernel = rc._odd_blocks_compiled.py_func
    for field in (pair + coils.UniformField(B=(0.0, 2e-3, 0.0)), pair.ideal()):
        mesh = RodMesh(5, (0.3,))  # (segments of two lengths)
        problem = build_problem(rod, field, mesh, np.zeros(3), 0.2)
        problem = problem.with_out_of_plane((0.77, 1.3, 1.0))
        U = problem.straight() + rng.normal(scale=0.3, size=(2, problem.size))
        lin = problem.linearize(U, np.array([2e5, -6e5]))
        oop = problem.out_of_plane
        monkeypatch.setattr(rc._odd_rental, "ready", False)
        monkeypatch.setattr(rc, "ODD_COMPILE_AFTER", np.inf)
        monkeypatch.setattr(rc._odd_rental, "held", lambda: False)
        D, E = oop.odd_blocks(lin)
        counts = oop.odd_count(lin)
        monkeypatch.setattr(rc._odd_rental, "ready", True)
        monkeypatch.setattr(rc, "_odd_blocks_compiled", python_kernel)
        Dc, Ec = oop.odd_blocks(lin)
        # (libm's sin and cos against numpy's: equal, or a last-bit difference on some CPUs)
        np.testing.assert_allclose(Dc, D, rtol=1e-13, atol=1e-13 * np.abs(D).max())
        np.testing.assert_allclose(Ec, E, rtol=1e-13, atol=1e-13 * np.abs(E).max())
        assert np.abs(D[:, :, 0, 0]).max() > 0 or field.linear  # (the hessian term is there)
        np.testing.assert_array_equal(oop.odd_count(lin), counts)


@pytest.fixture
def python_kernels(monkeypatch):
    """Every compiled kernel the mixed layout's corrector runs, as Python (.py_func; the coils'
    pass as its numpy near-zone twin): nothing compiles, and the engine's numpy path runs the
    same per-node arithmetic (libm's sines on both sides)."""
    import coilrod.rod._compiled as rc
    import coilrod.rod._inertia as ri
    import coilrod.rod._mixed_newton as mn
    from coils import _compiled as cc
    from coils._vectorised import near_pass

    def python_pass(pts, center, axis, fil, wind, beta, n0, params, flags, factor, B, G, H, err):
        err[:] = -1
        assert near_pass(pts, center, axis, fil, wind, params, flags, factor, B, G, H)
        return False

    for module in (rc, ri, mn):
        for name, obj in list(vars(module).items()):
            if hasattr(obj, "py_func") and name != "_newton":
                monkeypatch.setattr(module, name, obj.py_func)
    monkeypatch.setattr(cc, "coaxial_field", python_pass)
    monkeypatch.setattr(cx._rental, "ready", False)  # the engine's field: the numpy pass
    monkeypatch.setattr(cx, "COMPILE_AFTER", np.inf)
    monkeypatch.setattr(cx._rental, "held", lambda: False)
    for rental in (rc._rental, rc._odd_rental, ri._rental):  # the engine's: the kernels' Python
        monkeypatch.setattr(rental, "ready", True)
    return mn._newton.py_func


def test_mixed_corrector_is_the_engine_numpy_corrector(python_kernels, monkeypatch):
    # a coil pair, 4 segments: one state without chord steps (the final tangent the last
    # step's), stacks whose members converge at different iterations (the engine linearizes
    # them all again at the end) with a member not finite and one whose line search fails,
    # the Richardson mesh's chord start without tangent, and a sum with a uniform bias (chord
    # steps: the final tangent an earlier iterate's, the hessian evaluated for the 3D count)
    # and a Maxwell pair's ideal() field with the bias (a constant gradient: no hessian)
    import coilrod.rod._mixed_newton as mn
    from coilrod.path.corrector import NewtonOptions, newton

    rod = presets.seed_rod()
    pair = coils.HelmholtzPair(radius=2 * rod.length, turns=200, current=1.0, axis="y")
    scale = 4.0 / rod.magnetoelastic_number(pair.ideal().B0[1])
    problem = build_problem(rod, pair, make_mesh(rod, 4), np.zeros(3), 0.0)
    problem = problem.with_out_of_plane((0.77, 1.3, 1.0))
    straight = problem.straight()
    bad = straight.copy()
    bad[2::5] += 1.5  # (a kinked start)
    rng = np.random.default_rng(1)
    wild = straight + rng.normal(size=(2, straight.size))[1]  # (its line search fails)
    nan = straight.copy()
    nan[7] = np.nan
    cases = [
        (straight, 0.5 * scale, NewtonOptions(chord=0.0), True),  # (no chord steps)
        (np.stack([straight, bad, nan]), scale * np.array([0.01, 3.0, 1.0]), NewtonOptions(), True),
        (np.stack([straight, wild]), scale * np.array([1, 2]), NewtonOptions(backtracks=1), True),
        (straight, scale, NewtonOptions(chord_start=True), False),
    ]
    bias = coils.UniformField(B=(0.0, 1e-3, 0.0))
    assert mn.coaxial_groups(3.0 * (pair + 2.0 * bias)) == [(pair, 3.0), (bias, 6.0)]
    dipole = coils.Dipole(moment=(0.0, 0.0, 1.0), center=(0.0, 0.0, 1.0))
    assert mn.coaxial_groups(pair + dipole) is None
    biased = build_problem(rod, 0.5 * pair + bias, make_mesh(rod, 4), np.zeros(3), 0.0)
    cases = [(problem, *case) for case in cases]
    cases.append(
        (biased.with_out_of_plane((0.77, 1.3, 1.0)), straight, scale, NewtonOptions(), True)
    )
    maxwell = coils.MaxwellPair(radius=2 * rod.length, turns=200, current=1.0, axis="y")
    ideal = build_problem(rod, 3.0 * maxwell.ideal() + bias, make_mesh(rod, 4), np.zeros(3), 0.0)
    assert ideal.linear
    cases.append(
        (ideal.with_out_of_plane((0.77, 1.3, 1.0)), straight, scale, NewtonOptions(), True)
    )
    for problem, u0, s, opts, tangent in cases:
        # ski rental (a tiny price): the engine's numpy corrector runs and charges its
        # iterations, then the compiled one pays
        monkeypatch.setattr(mn, "COMPILE_AFTER", 1e-9)
        monkeypatch.setattr(mn._rental, "held", lambda: False)
        monkeypatch.setattr(mn._rental, "ready", False)
        monkeypatch.setattr(mn._rental, "spent", 0.0)
        ref = newton(problem, u0, s, opts, tangent_at_end=tangent)
        assert not mn._rental.ready
        assert mn._rental.spent > 0
        monkeypatch.setattr(mn, "_newton", python_kernels)
        monkeypatch.setattr(cx._rental, "ready", True)  # (the corrector asks for the coils')
        got = newton(problem, u0, s, opts, tangent_at_end=tangent)
        assert mn._rental.ready
        monkeypatch.setattr(cx._rental, "ready", False)
        assert getattr(got.lin, "path_rate", None) is not None or not tangent
        for name in ("u", "error", "ok", "iterations"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
        np.testing.assert_array_equal(got.lin.residual, ref.lin.residual)
        if not tangent:
            continue
        a, b = ref.lin, got.lin
        np.testing.assert_array_equal(b.load_rate, a.load_rate)
        np.testing.assert_array_equal(b.tangent.load_rate, a.tangent.load_rate)
        np.testing.assert_array_equal(b.tangent.det_signs(), a.tangent.det_signs())
        np.testing.assert_array_equal(b.tangent._lu[0], a.tangent.factor()[0])
        np.testing.assert_array_equal(b.tangent._lu[1], a.tangent._lu[1])
        with np.errstate(all="ignore"):
            rate = -problem.solve(a, a.load_rate)
        np.testing.assert_array_equal(b.path_rate, rate)
        for x, y in zip(b.field_values, a.field_values, strict=True):
            np.testing.assert_array_equal(x, y)
        # the hessian the 3D count reads (the engine's: evaluated there after chord steps)
        want = problem.out_of_plane._mixed_fields(a, len(a.u))[2]  # (None: a linear field)
        assert (want is None) == (b.field_hessian is None) == problem.linear
        if want is not None:
            np.testing.assert_array_equal(b.field_hessian, want.reshape(b.field_hessian.shape))
        # the 3D count (the kernel's; the engine's from the model's blocks and inertia)
        assert hasattr(b, "_counts_3d")
        for x, y in zip(problem.negative_counts(b), problem.negative_counts(a), strict=True):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(problem.stability(b), problem.stability(a))
