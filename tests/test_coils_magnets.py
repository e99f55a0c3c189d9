"""Permanent magnets (coils.Dipole, coils.CylinderMagnet): physics consistency and bad input.

Cross-checks:

* B against magpylib (Dipole, Cylinder, CylinderSegment of 360 deg for a ring), posed
  (position and rotation), inside and outside the material and near the axis: 1e-12;
* the gradient against 4th-order central differences of magpylib's B: 1e-8; the hessians
  (dipole, cylinder, ring) against 4th-order differences of the exact gradient (1e-10 for
  the magnets, on and near the axis too) and of magpylib's B twice (1e-8);
* the dipole on its axis against 2 mu0 m / (4 pi z^3); a ring is a cylinder less its bore;
* the far field of a magnet tends to its dipole as (size / distance)^2.
"""

from __future__ import annotations

import magpylib as magpy
import numpy as np
import pytest
from scipy.constants import mu_0
from scipy.spatial.transform import Rotation

from coils import CuboidMagnet, CylinderMagnet, Dipole

RNG = np.random.default_rng(7)
ROT = Rotation.from_rotvec([0.3, -0.5, 0.2])
CENTER = np.array([1e-3, 2e-3, -1e-3])
R, H, J, BORE = 5e-3, 8e-3, 1.3, 2e-3  # m, m, T (polarization), m
M = J / mu_0  # A/m


def _fd(f, x, h):
    return np.stack(
        [
            (-f(x + 2 * h * e) + 8 * f(x + h * e) - 8 * f(x - h * e) + f(x - 2 * h * e)) / (12 * h)
            for e in np.eye(3)
        ],
        axis=-1,
    )


def _pair(inner):
    ours = CylinderMagnet(2 * R, H, M, CENTER, inner_diameter=2 * inner, orientation=ROT)
    if inner == 0:
        ref = magpy.magnet.Cylinder(
            polarization=(0, 0, J), dimension=(2 * R, H), position=CENTER, orientation=ROT
        )
    else:
        ref = magpy.magnet.CylinderSegment(
            polarization=(0, 0, J),
            dimension=(inner, R, H, 0, 360),
            position=CENTER,
            orientation=ROT,
        )
    return ours, ref


def _points(magnet, n, margin):
    """n points within 2 sizes of the magnet, at least ``margin`` (m) from its surfaces,
    plus points on and near its axis."""
    local = RNG.uniform(-1.6, 1.6, size=(20 * n, 3)) * R
    rho, z = np.hypot(local[:, 0], local[:, 1]), np.abs(local[:, 2])
    far = np.ones(len(local), bool)
    for a in (R, magnet.inner_radius):
        if a > 0:
            far &= (np.abs(rho - a) > margin) | (z > H / 2 + margin)
    far &= (np.abs(z - H / 2) > margin) | (rho > R + margin)
    local = local[far][:n]
    axis = np.array([[0, 0, -9e-3], [0, 0, 2e-3], [1e-9, 0, 6e-3], [2e-8, -1e-8, -1e-3]])
    local = np.vstack([local, axis])
    return CENTER + local @ magnet.rotation.T


@pytest.mark.parametrize("inner", [0.0, BORE])
def test_cylinder_and_ring_B_match_magpylib(inner):
    ours, ref = _pair(inner)
    X = _points(ours, 40, 1e-6)
    Bref = ref.getB(X)
    assert np.abs(ours.B(X) - Bref).max() <= 1e-12 * np.abs(Bref).max()


@pytest.mark.parametrize("inner", [0.0, BORE])
def test_cylinder_and_ring_gradient_match_differences_of_magpylib(inner):
    ours, ref = _pair(inner)
    X = _points(ours, 20, 1e-3)
    G = ours.gradient(X)
    G_fd = _fd(ref.getB, X, 5e-6)
    assert np.abs(G - G_fd).max() <= 1e-8 * np.abs(G).max()
    B, G2 = ours.B_and_gradient(X)
    np.testing.assert_array_equal(G2, G)
    # curl- and divergence-free outside the surfaces
    assert np.abs(G - G.transpose(0, 2, 1)).max() <= 1e-14 * np.abs(G).max()
    assert np.abs(np.trace(G, axis1=1, axis2=2)).max() <= 1e-12 * np.abs(G).max()


@pytest.mark.parametrize("inner", [0.0, BORE])
def test_cylinder_and_ring_hessian_is_exact(inner):
    """Exact, not a difference of the gradient (that was 1e-7 off): against 4th-order
    differences of the exact gradient at 1e-10, off the axis and at rho / R = 0 .. 1e-3 (on
    both sides of the switch to the axis limit at 1e-4), inside and outside; against
    differences of magpylib's B twice; symmetric and traceless to rounding."""
    ours, ref = _pair(inner)
    X = _points(ours, 12, 1e-3)
    f = np.array([0.0, 1e-9, 1e-6, 9.9e-5, 1.01e-4, 1e-3])[:, None]
    for z in (2e-3, -6e-3):  # inside, outside (above the end)
        axial = np.column_stack([f * R * np.cos(1.0), f * R * np.sin(1.0), np.full_like(f, z)])
        X = np.vstack([X, CENTER + axial @ ours.rotation.T])
    B, G, Hs = ours.B_gradient_hessian(X)
    scale = np.abs(Hs).max()
    assert np.abs(Hs - _fd(ours.gradient, X, 2e-6)).max() <= 1e-10 * scale
    np.testing.assert_array_equal(ours.hessian(X), Hs)
    np.testing.assert_array_equal(G, ours.gradient(X))
    for perm in ((0, 2, 1, 3), (0, 1, 3, 2), (0, 3, 2, 1)):  # H_ijk symmetric in all three
        assert np.abs(Hs - Hs.transpose(perm)).max() <= 1e-15 * scale
    assert np.abs(np.einsum("kiij->kj", Hs)).max() <= 1e-14 * scale  # div B = 0
    Xm = X[:8]  # magpylib's B_rho loses precision within 1e-6 R of the axis: off it
    H_mp = _fd(lambda x: _fd(ref.getB, x, 1e-5), Xm, 1e-5)
    assert np.abs(Hs[:8] - H_mp).max() <= 1e-8 * scale


def test_cylinder_B_rho_keeps_its_precision_near_the_axis():
    """B_rho / rho tends to -dBz/dz / 2 on the axis (dBz/dz from the end loops, an
    independent kernel) as O(rho^2); the closed form lost eps R / rho relative there (6e-10
    at 1e-7 R, also in magpylib's), which the gradient and hessian inherit."""
    magnet = CylinderMagnet(2 * R, H, M)
    for z in (2e-3, 7e-3):
        limit = -0.5 * magnet.gradient([[0.0, 0.0, z]])[0, 2, 2]
        rho = R * np.array([1e-12, 1e-9, 1e-7, 1e-6])
        Br = magnet.B(np.column_stack([rho, 0 * rho, np.full_like(rho, z)]))[:, 0]
        assert np.all(np.abs(Br / rho / limit - 1) <= 1e-14 + (rho / R) ** 2)


def test_ring_is_a_cylinder_less_its_bore():
    X = _points(_pair(BORE)[0], 10, 1e-4)
    ring = CylinderMagnet(2 * R, H, M, CENTER, inner_diameter=2 * BORE, orientation=ROT)
    outer = CylinderMagnet(2 * R, H, M, CENTER, orientation=ROT)
    bore = CylinderMagnet(2 * BORE, H, M, CENTER, orientation=ROT)
    scale = np.abs(outer.B(X)).max()
    assert np.abs(ring.B(X) - (outer.B(X) - bore.B(X))).max() <= 1e-14 * scale
    gs = np.abs(outer.gradient(X)).max()
    assert np.abs(ring.gradient(X) - (outer.gradient(X) - bore.gradient(X))).max() <= 1e-13 * gs
    hs = np.abs(outer.hessian(X)).max()
    assert np.abs(ring.hessian(X) - (outer.hessian(X) - bore.hessian(X))).max() <= 1e-13 * hs


def test_dipole_matches_magpylib_closed_form_and_differences():
    m, c = np.array([0.1, -0.2, 0.3]), np.array([0.01, 0.0, -0.02])
    d = Dipole(m, c)
    X = RNG.normal(size=(8, 3)) * 0.05
    Bref = magpy.misc.Dipole(moment=m, position=c).getB(X)
    assert np.abs(d.B(X) - Bref).max() <= 1e-12 * np.abs(Bref).max()
    B, G, Hs = d.B_gradient_hessian(X)
    ref = magpy.misc.Dipole(moment=m, position=c)
    assert np.abs(G - _fd(ref.getB, X, 1e-5)).max() <= 1e-8 * np.abs(G).max()
    assert np.abs(Hs - _fd(d.gradient, X, 1e-5)).max() <= 1e-8 * np.abs(Hs).max()
    z = 0.07
    axial = Dipole((0.0, 0.0, 2.0), (0.0, 0.0, 0.0)).B([0.0, 0.0, z])[0]
    np.testing.assert_allclose(axial, [0, 0, 2 * mu_0 * 2.0 / (4 * np.pi * z**3)], rtol=1e-15)


def test_far_field_tends_to_the_dipole():
    magnet = CylinderMagnet(2 * R, H, M, CENTER, inner_diameter=2 * BORE, orientation=ROT)
    dipole = magnet.dipole()
    np.testing.assert_allclose(
        dipole.moment, M * np.pi * (R**2 - BORE**2) * H * magnet.axis, rtol=1e-15
    )
    direction = np.array([0.3, -0.4, 0.866])
    errors, errors_H = [], []
    for dist in (0.1, 0.2):
        X = CENTER + dist * direction[None, :]
        B, G = magnet.B_and_gradient(X)
        Bd, Gd = dipole.B_and_gradient(X)
        errors.append(np.abs(B - Bd).max() / np.abs(Bd).max())
        assert np.abs(G - Gd).max() <= 1e-2 * np.abs(Gd).max()
        Hm, Hd = magnet.hessian(X), dipole.hessian(X)
        errors_H.append(np.abs(Hm - Hd).max() / np.abs(Hd).max())
    assert errors[0] < 1e-2
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)  # O((size/distance)^2)
    assert errors_H[0] < 2e-2
    assert errors_H[0] / errors_H[1] == pytest.approx(4.0, rel=0.05)


def test_orientation_turns_the_magnetisation():
    flip = CylinderMagnet(2 * R, H, M, orientation=Rotation.from_rotvec([np.pi, 0, 0]))
    minus = CylinderMagnet(2 * R, H, -M)
    down = CylinderMagnet(2 * R, H, M, axis="-z")
    X = RNG.normal(size=(5, 3)) * 0.02
    np.testing.assert_allclose(flip.B(X), minus.B(X), rtol=0, atol=1e-12 * np.abs(minus.B(X)).max())
    np.testing.assert_allclose(flip.axis, [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(down.B(X), minus.B(X), rtol=0, atol=1e-12 * np.abs(minus.B(X)).max())


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="inner_diameter must be in"):
        CylinderMagnet(2 * R, H, M, inner_diameter=2 * R)
    with pytest.raises(ValueError, match="orientation must be a rotation matrix"):
        CylinderMagnet(2 * R, H, M, orientation=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="axis or orientation, not both"):
        CylinderMagnet(2 * R, H, M, axis="x", orientation=np.eye(3))
    with pytest.raises(ValueError, match="diameter must be positive"):
        CylinderMagnet(-R, H, M)
    with pytest.raises(ValueError, match=r"points\[1\].*on an edge circle"):
        CylinderMagnet(2 * R, H, M).gradient([[0.0, 0.0, 0.0], [R, 0.0, H / 2]])
    with pytest.raises(ValueError, match=r"points\[0\].*at the dipole's centre"):
        Dipole((0, 0, 1), (0.1, 0.0, 0.0)).B([0.1, 0.0, 0.0])
    with pytest.raises(AttributeError, match="immutable"):
        CylinderMagnet(2 * R, H, M).magnetization = 1.0


def test_readme_magnet_example_runs(capsys):
    """The README's magnet and eMNS block runs and prints the numbers its text quotes."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    block = next(b for b in re.findall(r"```python\n(.*?)```", text, re.S) if "dipole()" in b)
    exec(compile(block, "README.md", "exec"), {})  # noqa: S102
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("[6.79 4.91] [-0.684")
    assert out[1].startswith("[6.71 4.87] [-0.671")
    assert out[2].endswith("[ 0.  0. 20.]")
    assert "1.2 % low in B and 1.9 % in the gradient" in " ".join(text.split())


def _cuboid_and_magpylib():
    """A posed cuboid magnetised along no axis, and magpylib's model of the same magnet."""
    size = np.array([6e-3, 8e-3, 10e-3])
    Mv = np.array([0.4, -0.7, 1.0]) / mu_0
    ours = CuboidMagnet(size, Mv, CENTER, orientation=ROT)
    ref = magpy.magnet.Cuboid(
        polarization=mu_0 * Mv, dimension=size, position=CENTER, orientation=ROT
    )
    return size, ours, ref


def test_cuboid_B_and_gradient_match_magpylib():
    """Any magnetisation direction, posed; points also in the face planes and on the lines of
    edges outside the magnet (where the closed form's terms are rewritten)."""
    size, ours, ref = _cuboid_and_magpylib()
    local = RNG.uniform(-1.5, 1.5, size=(60, 3)) * size
    special = [[0.01, 0.0, 5e-3], [0.01, 4e-3, 0.0], [3e-3, 4e-3, 0.02], [0.0, 0.0, 0.01]]
    local = np.vstack([local, special, [[0.0, 0.0, 0.0]]])
    X = CENTER + local @ ours.rotation.T
    Bref = ref.getB(X)
    assert np.abs(ours.B(X) - Bref).max() <= 1e-12 * np.abs(Bref).max()
    away = np.min(np.abs(np.abs(local) - size / 2), axis=1) > 1e-3
    Xg = X[away][:25]
    G = ours.gradient(Xg)
    assert np.abs(G - _fd(ref.getB, Xg, 2e-6)).max() <= 1e-8 * np.abs(G).max()
    Xs = CENTER + np.array(special) @ ours.rotation.T
    Gs = ours.gradient(Xs)
    assert np.abs(Gs - _fd(ref.getB, Xs, 2e-6)).max() <= 1e-8 * np.abs(Gs).max()
    far = CENTER + 0.2 * np.array([[0.6, 0.0, 0.8]])
    Gd = ours.dipole().gradient(far)
    assert np.abs(ours.gradient(far) - Gd).max() <= 1e-2 * np.abs(Gd).max()


def test_cuboid_hessian_is_exact():
    """Against 4th-order differences of the exact gradient (1e-10; the difference hessian
    was 1e-7 off), in the face planes and on the lines of edges too, and of magpylib's B
    twice (1e-8); symmetric and traceless; far away the dipole's, as (size / distance)^2."""
    size, ours, ref = _cuboid_and_magpylib()
    local = RNG.uniform(-1.5, 1.5, size=(60, 3)) * size
    local = local[np.min(np.abs(np.abs(local) - size / 2), axis=1) > 1e-3][:12]
    special = [[0.01, 0.0, 5e-3], [0.01, 4e-3, 0.0], [3e-3, 4e-3, 0.02], [0.0, 0.0, 0.01]]
    X = CENTER + np.vstack([local, special, [[0.0, 0.0, 0.0]]]) @ ours.rotation.T
    B, G, Hs = ours.B_gradient_hessian(X)
    scale = np.abs(Hs).max(axis=(1, 2, 3))[:, None, None, None]
    assert np.all(np.abs(Hs - _fd(ours.gradient, X, 2e-6)) <= 1e-10 * scale)
    np.testing.assert_array_equal(ours.hessian(X), Hs)
    np.testing.assert_array_equal(G, ours.gradient(X))
    for perm in ((0, 2, 1, 3), (0, 1, 3, 2), (0, 3, 2, 1)):
        assert np.all(np.abs(Hs - Hs.transpose(perm)) <= 1e-15 * scale)
    assert np.all(np.abs(np.einsum("kiij->kj", Hs)) <= 1e-14 * scale[:, :, 0, 0])
    Xm = X[:8]
    H_mp = _fd(lambda x: _fd(ref.getB, x, 1e-5), Xm, 1e-5)
    assert np.abs(Hs[:8] - H_mp).max() <= 1e-8 * np.abs(Hs).max()
    errors = []
    for dist in (0.1, 0.2):
        far = CENTER + dist * np.array([[0.6, 0.0, 0.8]])
        Hd = ours.dipole().hessian(far)
        errors.append(np.abs(ours.hessian(far) - Hd).max() / np.abs(Hd).max())
    assert errors[0] < 1e-2
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)


def test_cuboid_edge_is_refused():
    with pytest.raises(ValueError, match=r"points\[0\].*on an edge of the cuboid"):
        CuboidMagnet((2e-3, 2e-3, 2e-3), (0, 0, 1e6)).B([1e-3, 0.0, 1e-3])
    # the edges parallel to M carry no charge: the field is finite there
    assert np.isfinite(CuboidMagnet((2e-3, 2e-3, 2e-3), (0, 0, 1e6)).B([1e-3, 1e-3, 0.0])).all()
    with pytest.raises(ValueError, match="size must be three positive"):
        CuboidMagnet((2e-3, 0.0, 2e-3), (0, 0, 1e6))
