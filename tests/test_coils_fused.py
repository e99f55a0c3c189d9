"""The fused ``B_gradient_hessian`` and the compiled kernel behind every coil.

Cross-checks:
- against independent references: a system of differently oriented pairs, a scaled pair and a
  uniform field, with B from magpylib, the gradient from Richardson differences of magpylib's
  B and the hessian from the mpmath Biot-Savart integral (tests/_mp_loop_ref.py);
- the protocol: the fused method returns what B, gradient and hessian return (every source,
  sums and scalings), with the same errors naming the same point;
- numba is imported when a coil is first evaluated, never by ``import coils`` or by ideal
  fields (checked in a fresh interpreter).
"""

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from _magpylib_ref import magpylib_B, magpylib_gradient
from _mp_loop_ref import loops
from scipy.constants import mu_0

import coils


def reference_hessian(field, point):
    """H (3, 3, 3) of every coaxial group in ``field`` at ``point`` from the mpmath integral
    (group frame -> global: ``H_IJL = R_Ii R_Jj R_Ll h_ijl``)."""
    from coils.coaxial import coaxial_parts

    H = np.zeros((3, 3, 3))
    for part in coaxial_parts(field):
        R = part.rotation
        _, _, h = loops((point - part.center) @ R, part.filaments)
        scale = field.factor if isinstance(field, coils.ScaledField) else 1.0
        H += scale * np.einsum("Ii,Jj,Ll,ijl->IJL", R, R, R, h)
    return H


def test_system_against_independent_references(rng):
    helmholtz = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
    maxwell = coils.MaxwellPair(0.12, 80, -1.5, axis=(0.3, -0.5, 0.8), center=(0.01, 0, 0.02))
    uniform = coils.UniformField((1e-3, 0.0, -2e-3))
    system = coils.CoilSystem([helmholtz, maxwell, uniform])
    pts = rng.uniform(-0.04, 0.04, (60, 3))
    B, G, H = system.B_gradient_hessian(pts)
    coils_only = coils.CoilSystem([helmholtz, maxwell])
    Bm = magpylib_B(coils_only, pts) + uniform.B0
    np.testing.assert_allclose(B, Bm, rtol=0, atol=1e-13 * np.abs(Bm).max())
    Gm = magpylib_gradient(coils_only, pts, step=1e-4 * system.length_scale)
    np.testing.assert_allclose(G, Gm, rtol=0, atol=1e-10 * np.abs(Gm).max())
    for k in (0, 17, 59):
        Hr = reference_hessian(coils_only, pts[k])
        assert np.abs(H[k] - Hr).max() < 1e-13 * np.abs(Hr).max()


def test_scaled_pair_against_reference():
    pair = coils.MaxwellPair(0.1, 50, 2.0, axis="z")
    scaled = -2.5 * pair
    point = np.array([0.013, -0.02, 0.031])
    B, G, H = scaled.B_gradient_hessian(point)
    Br, Gr, Hr = loops(point, pair.filaments)
    np.testing.assert_allclose(B[0], -2.5 * Br, rtol=1e-14, atol=1e-14 * np.abs(Br).max())
    np.testing.assert_allclose(G[0], -2.5 * Gr, rtol=0, atol=1e-14 * np.abs(Gr).max())
    np.testing.assert_allclose(H[0], -2.5 * Hr, rtol=0, atol=1e-14 * np.abs(Hr).max())


FIELDS = {
    "coil": lambda: coils.Coil(0.05, 30, -1.5, axis=(0.3, -0.5, 0.8), center=(0.01, 0.02, -0.03)),
    "helmholtz winding": lambda: coils.HelmholtzPair(
        0.08, 200, 1.0, axis="x", winding=(0.02, 0.015), filaments=(3, 2)
    ),
    "system": lambda: coils.CoilSystem(
        [coils.HelmholtzPair(0.1, 100, 2.0, axis="y"), coils.MaxwellPair(0.1, 100, 1.0, axis="z")]
    ),
    "sum with linear": lambda: (
        coils.MaxwellPair(0.1, 100, 1.0)
        + coils.LinearField(B0=(0, 1e-3, 0), gradient=np.diag([1.0, -0.5, -0.5]))
        + 0.5 * coils.HelmholtzPair(0.2, 10, 1.0, axis="x")
    ),
    "scaled sum": lambda: 3.0 * (coils.Coil(0.1, 5, 1.0) + coils.UniformField((0, 0, 1e-3))),
    "uniform": lambda: coils.UniformField((0, 5e-3, 0)),
    "linear": lambda: coils.LinearField(B0=(1e-3, 0, 0), gradient=np.diag([-0.5, 1.0, -0.5])),
}


@pytest.mark.parametrize("name", FIELDS)
def test_fused_equals_separate_methods(name, rng):
    # a protocol guarantee: one pass returns exactly what the three methods return
    field = FIELDS[name]()
    pts = rng.uniform(-0.04, 0.04, (50, 3))
    B, G, H = field.B_gradient_hessian(pts)
    assert B.shape == (50, 3)
    assert G.shape == (50, 3, 3)
    assert H.shape == (50, 3, 3, 3)
    np.testing.assert_array_equal(B, field.B(pts))
    np.testing.assert_array_equal(G, field.gradient(pts))
    np.testing.assert_array_equal(H, field.hessian(pts))
    B2, G2 = field.B_and_gradient(pts)
    np.testing.assert_array_equal(B2, B)
    np.testing.assert_array_equal(G2, G)


def test_single_point_and_lists():
    pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
    B, G, H = pair.B_gradient_hessian([0.01, 0.0, 0.02])
    assert B.shape == (1, 3)
    assert G.shape == (1, 3, 3)
    assert H.shape == (1, 3, 3, 3)


@pytest.mark.parametrize(
    ("field", "point", "match"),
    [
        (coils.Coil(0.1, 1, 1.0, axis="z"), [0.0, 0.1, 0.0], "point 2 lies on a coil winding"),
        (
            coils.Coil(0.1, 50, 1.0, axis="y", winding=(0.01, 0.01)),
            [0.1, 0.002, 0.0],
            r"point 2 lies inside a coil winding \(0.01 m x 0.01 m section",
        ),
        (
            coils.CoilSystem([coils.UniformField((0, 1, 0)), coils.MaxwellPair(0.1, 10, 1.0)]),
            [0.1, 0.1 * np.sqrt(3) / 2, 0.0],
            "point 2 lies on a coil winding",
        ),
    ],
)
def test_errors_name_the_point(field, point, match):
    pts = np.array([[0.0, 0.0, 0.01], [0.02, 0.0, 0.0], point, [0.0, 0.1, 0.0]])
    for method in (field.B_gradient_hessian, field.B, field.gradient, field.hessian):
        with pytest.raises(ValueError, match=match):
            method(pts)


def test_bad_points():
    pair = coils.HelmholtzPair(0.1, 100, 2.0)
    with pytest.raises(ValueError, match="points must be finite; row 1"):
        pair.B_gradient_hessian([[0, 0, 0], [0, np.nan, 0]])
    with pytest.raises(ValueError, match=r"points must have shape \(n, 3\)"):
        pair.B_gradient_hessian(np.zeros((3, 2)))


def test_coil_arrays_are_read_only():
    # the compiled kernel's data are derived once from them
    coil = coils.Coil(0.1, 10, 1.0)
    with pytest.raises(ValueError, match="read-only"):
        coil.filaments[0, 2] = 5.0
    center = np.array([0.0, 0.0, 1.0])
    coils.Coil(0.1, 10, 1.0, center=center)
    center[0] = 1.0  # the caller's array stays writable


def test_numba_is_imported_only_when_a_coil_is_evaluated():
    code = textwrap.dedent(
        """
        import sys
        import coils
        u = coils.UniformField((0, 1e-3, 0))
        lin = coils.LinearField(B0=(0, 0, 0), gradient=coils.maxwell_gradient(1.0))
        s = u + lin
        s.B([[0.0, 0.1, 0.0]]); s.B_gradient_hessian([[0.0, 0.1, 0.0]]); lin.hessian([0, 0, 0])
        pair = coils.HelmholtzPair(0.1, 100, 2.0) + u
        print("numba" in sys.modules)
        pair.B([[0.0, 0.0, 0.0]])
        print("numba" in sys.modules)
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600
    )
    assert out.stdout.split() == ["False", "True"]


@pytest.fixture
def force_pass(monkeypatch):
    """``force_pass("numpy")`` or ``force_pass("compiled")``: which pass evaluates coils from
    now on (coils.coaxial decides otherwise by the cost of the numpy passes so far)."""
    import math

    import coils.coaxial as cx

    def force(name):
        monkeypatch.setattr(cx._rental, "held", lambda: False)
        monkeypatch.setattr(cx._rental, "spent", 0.0)
        monkeypatch.setattr(cx._rental, "ready", name == "compiled")
        monkeypatch.setattr(cx, "COMPILE_AFTER", math.inf)

    return force


def branch_points(radius):
    """Points (local frame of a loop of ``radius`` at the origin) in every branch of the
    kernel: on and near the axis (w = 0, 1e-250 and the series about 0), each series table
    (w from 2^-8 to 3/4), the closed forms near the wire, and beyond."""
    w = np.concatenate([[0.0, 1e-250, 1e-30, 1e-6], np.geomspace(2.0**-8, 0.74, 25)])
    w = np.concatenate([w, [0.76, 0.9, 0.999, 1.0 - 1e-8]])
    # points with t = 2 a rho / s = sqrt(w) at a few heights z (rho from the quadratic)
    out = []
    for z in (0.0, 0.3 * radius, -1.7 * radius):
        t = np.sqrt(w)
        c = radius**2 + z**2
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = np.where(t > 0, (radius - np.sqrt(np.maximum(radius**2 - t * t * c, 0))) / t, 0)
        rho = np.where(t > 0, rho, 0.0)
        out.append(np.column_stack([rho, np.zeros_like(rho), np.full_like(rho, z)]))
    return np.concatenate(out)


def test_numpy_and_compiled_passes_agree(force_pass):
    # the numpy pass (cold start) and the compiled pass give the same field to the last bit
    # (a process's numbers do not change when it compiles), in every branch, for B, G, H
    # alone and together, scaled; and both match the mpmath reference
    pair = coils.HelmholtzPair(0.1, 50, 2.0, axis=(0.3, -0.5, 0.8), center=(0.01, 0, -0.02))
    field = -1.5 * (pair + coils.Coil(0.04, 20, 1.0, axis="x"))
    local = branch_points(0.05) + [0, 0, 0.05]  # about the upper loop of the pair
    pts = local @ pair.rotation.T + pair.center
    keep = ~coils.coaxial.winding_mask(field, pts, 1e-6)
    local, pts = local[keep], pts[keep]
    results = {}
    for name in ("numpy", "compiled"):
        force_pass(name)
        results[name] = [field.B_gradient_hessian(pts), field.B(pts), field.gradient(pts)]
        results[name].append(field.hessian(pts))
    (Bn, Gn, Hn), *alone_n = results["numpy"]
    (Bc, Gc, Hc), *alone_c = results["compiled"]
    for x, ref in [(Bn, Bc), (Gn, Gc), (Hn, Hc), *zip(alone_n, alone_c, strict=True)]:
        np.testing.assert_array_equal(x, ref)
    # the pair alone against the mpmath Biot-Savart integral, both passes, near the wire (the
    # other branches are checked against it in test_coils_stability)
    R = pair.rotation
    for k in (len(local) // 3 - 2,):
        Br, Gr, Hr = loops(local[k], pair.filaments)
        ref = (R @ Br, R @ Gr @ R.T, np.einsum("Ii,Jj,Ll,ijl->IJL", R, R, R, Hr))
        for name in ("numpy", "compiled"):
            force_pass(name)
            got = pair.B_gradient_hessian(pts[k])
            for x, r in zip(got, ref, strict=True):
                assert np.abs(x[0] - r).max() <= 1e-13 * np.abs(r).max(), name


def test_rental_decides_as_each_site_did(monkeypatch):
    # coils._numba_cache.Rental against the rules the six sites spelled out before it (numpy
    # iff rent + cost <= price and not cached; the planar corrector, charged afterwards: iff
    # rent < price and not cached; an announced horizon compiles iff rent + calls > price),
    # at the boundaries (equal, 0, inf); the cache is asked only where the price allows rent
    import math
    import types

    import coils._numba_cache as nc

    def probe(answer, asked):  # a cache that holds the kernel or not, and counts the questions
        return lambda: asked.append(answer) or answer

    owner = types.ModuleType("rental_test_owner")
    monkeypatch.setitem(sys.modules, owner.__name__, owner)
    for price in (0.0, 1.0, 2.0, math.inf):
        owner.COMPILE_AFTER = price
        for spent in (0.0, 0.5, 1.0, 2.0):
            for seconds in (0.0, 0.5, 1.0):
                for held in (False, True):
                    rental = nc.Rental(owner.__name__, lambda: None)
                    asked = []
                    rental.held = probe(held, asked)
                    rental.charge(spent)
                    rents = spent < price if seconds == 0.0 else spent + seconds <= price
                    pays = rental.pays(seconds)
                    assert pays == (held or not rents)
                    assert rental.ready == pays
                    assert asked == ([held] if rents else [])
                    rental = nc.Rental(owner.__name__, lambda: None)  # rent: pays, else charge
                    rental.held = probe(held, [])
                    rental.charge(spent)
                    assert rental.rent(seconds) == (held or not rents)
                    assert rental.spent == (spent if rental.ready else spent + seconds)
                    rental = nc.Rental(owner.__name__, lambda: None)
                    rental.charge(spent)
                    rental.expect(seconds)
                    assert rental.ready == (spent + seconds > price)


def test_compiling_starts_when_it_pays(force_pass, monkeypatch):
    # numpy passes until their estimated cost reaches COMPILE_AFTER, then the compiled pass;
    # a point the numpy pass leaves (far zone) goes to the compiled pass at once
    import coils._vectorised as vec
    import coils.coaxial as cx

    calls = []
    near_pass = vec.near_pass
    monkeypatch.setattr(vec, "near_pass", lambda *a: calls.append(near_pass(*a)) or calls[-1])
    force_pass("numpy")
    pair = coils.HelmholtzPair(0.1, 50, 2.0, axis="z")
    pts = np.zeros((10, 3))
    monkeypatch.setattr(cx, "COMPILE_AFTER", 2.5 * (cx._NUMPY_CALL_S + cx._NUMPY_POINT_S * 20))
    B0 = pair.B(pts)
    pair.B(pts)
    assert calls == [True, True]
    assert not cx._rental.ready
    np.testing.assert_allclose(pair.B(pts), B0, rtol=1e-14)  # third call: compiled
    assert calls == [True, True]
    assert cx._rental.ready
    force_pass("numpy")
    B_far = pair.B([[0.0, 0.0, 1.0]])
    assert calls[-1] is False  # and from now on the compiled pass, compiled anyway
    assert cx._rental.ready
    z0, a, current = pair.filaments.T  # on the axis: mu0 I a^2 / (2 ((z - z0)^2 + a^2)^1.5)
    Bz = np.sum(mu_0 * current * a**2 / (2 * ((1.0 - z0) ** 2 + a**2) ** 1.5))
    np.testing.assert_allclose(B_far[0], [0, 0, Bz], rtol=1e-14, atol=0)
