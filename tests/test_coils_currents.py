"""Coil systems under current control: channels, linearity, presets, power, currents for a target.

Cross-checks, each against something independent of the code it tests:
- what a channel is: pairs and coils are channels (nested systems contribute theirs), ideal
  and scaled parts are fixed; ``with_currents`` equals the system built with those currents;
- linearity: ``unit_fields`` equals the field of ``with_currents(e_j)`` less the fixed parts,
  and ``B(I) = B_fixed + unit_fields @ I`` (B, gradient, hessian) for random currents; one
  compiled pass per channel (counted, not timed);
- magpylib: the unit fields of every preset against magpylib loops placed from the preset's
  documented geometry (not from our filaments); gradients by Richardson differences;
- closed forms at the preset centres: Helmholtz (4/5)^{3/2} mu0 N I / R per pair, Maxwell
  48 sqrt(3)/7^{5/2} mu0 N I / R^2 diag(-1/2, 1, -1/2), a loop's on-axis field and gradient for
  each hemisphere coil; the presets' wires keep clear of each other (sampled rings);
- power: sum R I^2 against resistances computed by hand from the wire;
- currents_for: reproduces the target; is the minimum-power solution (scipy SLSQP, the
  closed form of two coaxial pairs, KKT); within active limits it matches a brute-force
  enumeration of active sets; the largest reachable fraction against its closed form;
- bad input: ValueError naming the argument or the channel.
"""

import itertools
import math

import numpy as np
import pytest
from _magpylib_ref import magpylib_B, magpylib_gradient
from scipy.constants import mu_0

import coils
from coils import presets
from coils.copper import COPPER_RESISTIVITY

HELMHOLTZ = (4 / 5) ** 1.5
MAXWELL = 48 * math.sqrt(3) / 7**2.5


def mixed_system():
    """Channels of every kind (pairs with and without windings, a tilted coil, a turn-by-turn
    pair) and fixed parts of every kind."""
    return coils.CoilSystem(
        [
            coils.HelmholtzPair(0.1, 120, 1.5, axis="x", wire_diameter=1e-3),
            coils.MaxwellPair(0.14, 90, -2.0, axis="y", winding=(0.01, 0.012)),
            coils.Coil(0.05, 60, 0.7, axis=(0.3, -0.4, 0.9), center=(0.02, 0.01, -0.18)),
            coils.HelmholtzPair(0.12, 12, 3.0, axis="z", winding=(0.01, 0.01), turn_layout=(4, 3)),
            coils.UniformField((1e-4, -2e-4, 3e-4)),
            coils.LinearField(B0=(0, 1e-4, 0), gradient=coils.maxwell_gradient(0.02)),
            0.5 * coils.MaxwellPair(0.2, 50, 1.0, axis="z"),
        ]
    )


def points(rng, n=40, half=0.03):
    return rng.uniform(-half, half, (n, 3))


class _Collection:
    """Something with ``to_magpylib`` for the references of tests/_magpylib_ref.py."""

    def __init__(self, collection):
        self.collection = collection

    def to_magpylib(self):
        return self.collection


def magpylib_loops(loops):
    """A magpylib Collection of circular loops ``(centre, axis, radius, ampere_turns)``,
    placed by rotating magpylib's z-axis loop onto ``axis``."""
    import magpylib as magpy
    from scipy.spatial.transform import Rotation

    out = []
    for centre, axis, radius, at in loops:
        loop = magpy.current.Circle(current=float(at), diameter=2.0 * radius)
        axis = np.asarray(axis, float) / np.linalg.norm(axis)
        if not np.allclose(axis, (0, 0, 1)):
            rot, _ = Rotation.align_vectors([axis], [[0.0, 0.0, 1.0]])
            loop.rotate(rot, anchor=(0.0, 0.0, 0.0))
        loop.move(np.asarray(centre, float))
        out.append(loop)
    return _Collection(magpy.Collection(*out))


def pair_loops(centre, axis, radius, turns, spacing, sign):
    axis = np.asarray(axis, float)
    c = np.asarray(centre, float)
    return [
        (c + spacing / 2 * axis, axis, radius, turns),
        (c - spacing / 2 * axis, axis, radius, sign * turns),
    ]


def documented_geometry(name):
    """Per channel, the loops (at 1 A) that the presets' docstrings describe."""
    unit = np.eye(3)
    if name == "three_axis_helmholtz":
        return [pair_loops(0, unit[k], r, 200, r, 1) for k, r in enumerate((0.10, 0.14, 0.18))]
    if name == "helmholtz_maxwell":
        chans = documented_geometry("three_axis_helmholtz")
        return chans + [pair_loops(0, unit[1], 0.24, 500, math.sqrt(3) * 0.24, -1)]
    chans = []
    for polar, azimuth in [(90, 0), (90, 90), (90, 180), (90, 270)] + [
        (45, 45),
        (45, 135),
        (45, 225),
        (45, 315),
    ]:
        t, p = math.radians(polar), math.radians(azimuth)
        toward = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
        chans.append([(-0.2 * toward, toward, 0.06, 600)])
    return chans


PRESETS = ["three_axis_helmholtz", "helmholtz_maxwell", "eight_coil_hemisphere"]


# -- what a channel is ---------------------------------------------------------------------------
class TestChannels:
    def test_pairs_and_coils_are_channels_ideal_parts_are_fixed(self):
        system = mixed_system()
        assert len(system.channels) == 4
        np.testing.assert_array_equal(system.currents, [1.5, -2.0, 0.7, 3.0])
        assert len(system.fixed_parts) == 3
        assert system.names[0] == "HelmholtzPair axis +x"
        assert system.names[2].startswith("Coil axis (")
        np.testing.assert_array_equal(system.max_current, np.inf)

    def test_three_helmholtz_pairs_are_three_channels(self):
        system = coils.CoilSystem([coils.HelmholtzPair(0.1, 10, 1.0, axis=a) for a in "xyz"])
        assert system.currents.shape == (3,)

    def test_currents_is_a_copy(self):
        system = mixed_system()
        current = system.currents
        current[:] = 99.0
        np.testing.assert_array_equal(system.currents, [1.5, -2.0, 0.7, 3.0])
        limits = presets.three_axis_helmholtz().max_current
        limits[:] = 0.0  # no effect on a new call either
        np.testing.assert_array_equal(presets.three_axis_helmholtz().max_current, 10.0)

    def test_with_currents_equals_the_system_built_with_them(self, rng):
        system = mixed_system()
        new_currents = np.array([-0.3, 1.1, 2.5, -0.4])
        changed = system.with_currents(new_currents)
        np.testing.assert_array_equal(changed.currents, new_currents)
        np.testing.assert_array_equal(system.currents, [1.5, -2.0, 0.7, 3.0])  # unchanged
        built = coils.CoilSystem(
            [
                coils.HelmholtzPair(0.1, 120, -0.3, axis="x", wire_diameter=1e-3),
                coils.MaxwellPair(0.14, 90, 1.1, axis="y", winding=(0.01, 0.012)),
                coils.Coil(0.05, 60, 2.5, axis=(0.3, -0.4, 0.9), center=(0.02, 0.01, -0.18)),
                coils.HelmholtzPair(
                    0.12, 12, -0.4, axis="z", winding=(0.01, 0.01), turn_layout=(4, 3)
                ),
                *system.parts[4:],
            ]
        )
        for a, b in zip(changed.channels, built.channels, strict=True):
            np.testing.assert_array_equal(a.filaments, b.filaments)
            assert a.resistance == b.resistance
        pts = points(rng)
        np.testing.assert_array_equal(changed.B(pts), built.B(pts))
        np.testing.assert_array_equal(changed.gradient(pts), built.gradient(pts))

    def test_nested_systems_contribute_their_channels_limits_and_names(self):
        inner = coils.CoilSystem(
            [coils.HelmholtzPair(0.1, 10, 1.0, axis="x"), coils.UniformField((0, 0, 1e-3))],
            max_current=2.0,
            names=["inner x"],
        )
        outer = coils.CoilSystem([inner, coils.MaxwellPair(0.2, 10, 1.0, axis="z")])
        assert outer.names == ("inner x", "MaxwellPair axis +z")
        np.testing.assert_array_equal(outer.max_current, [2.0, np.inf])
        assert len(outer.fixed_parts) == 1
        # limits only tighten
        tighter = coils.CoilSystem([inner, coils.Coil(0.1, 1, 0.0)], max_current=[5.0, 3.0])
        np.testing.assert_array_equal(tighter.max_current, [2.0, 3.0])
        changed = outer.with_currents([-1.5, 4.0])
        np.testing.assert_array_equal(changed.currents, [-1.5, 4.0])
        assert isinstance(changed.parts[0], coils.CoilSystem)
        np.testing.assert_array_equal(changed.parts[0].currents, [-1.5])
        with pytest.raises(
            ValueError, match=r"currents\[0\] = 2.5 A exceeds .* \(channel 0: inner"
        ):
            outer.with_currents([2.5, 0.0])

    def test_with_limits(self):
        inner = coils.CoilSystem([coils.HelmholtzPair(0.1, 10, 1.0, axis="x")], max_current=2.0)
        outer = coils.CoilSystem([inner, coils.Coil(0.1, 10, 0.5)], max_current=[1.5, 1.0])
        wider = outer.with_limits([50.0, np.inf])
        np.testing.assert_array_equal(wider.max_current, [50.0, np.inf])  # nested ones too
        np.testing.assert_array_equal(wider.with_currents([40.0, 1e3]).currents, [40.0, 1e3])
        np.testing.assert_array_equal(outer.max_current, [1.5, 1.0])  # unchanged
        np.testing.assert_array_equal(wider.center, outer.center)
        assert wider.names == outer.names
        with pytest.raises(ValueError, match=r"carries 0.5 A, above its max_current 0.1 A"):
            outer.with_limits([1.0, 0.1])

    def test_with_current_of_a_coil(self):
        pair = coils.MaxwellPair(0.1, 40, 2.0, axis="z", winding=(0.01, 0.01), filaments=(2, 3))
        other = pair.with_current(-0.5)
        assert isinstance(other, coils.MaxwellPair)
        built = coils.MaxwellPair(0.1, 40, -0.5, axis="z", winding=(0.01, 0.01), filaments=(2, 3))
        np.testing.assert_array_equal(other.filaments, built.filaments)
        assert pair.current == 2.0
        assert not other.filaments.flags.writeable


# -- linearity -----------------------------------------------------------------------------------
class TestLinearity:
    def test_unit_fields_are_the_fields_of_unit_currents(self, rng):
        system = mixed_system()
        pts = points(rng)
        Bu, Gu, Hu = system.unit_fields(pts, hessian=True)
        m = len(system.channels)
        assert Bu.shape == (len(pts), 3, m)
        assert Gu.shape == (len(pts), 3, 3, m)
        assert Hu.shape == (len(pts), 3, 3, 3, m)
        Bf, Gf = system.fixed_field(pts)
        Hf = system.with_currents(np.zeros(m)).hessian(pts)
        for j in range(m):
            one = system.with_currents(np.eye(m)[j])
            B, G, H = one.B_gradient_hessian(pts)
            np.testing.assert_allclose(Bu[..., j], B - Bf, rtol=0, atol=1e-14 * np.abs(B).max())
            np.testing.assert_allclose(Gu[..., j], G - Gf, rtol=0, atol=1e-14 * np.abs(G).max())
            np.testing.assert_allclose(Hu[..., j], H - Hf, rtol=0, atol=1e-13 * np.abs(H).max())

    def test_superposition_for_random_currents(self, rng):
        system = mixed_system()
        pts = points(rng)
        Bu, Gu, Hu = system.unit_fields(pts, hessian=True)
        Bf, Gf = system.fixed_field(pts)
        Hf = system.with_currents(np.zeros(4)).hessian(pts)
        for _ in range(3):
            current = rng.uniform(-5, 5, 4)
            B, G, H = system.with_currents(current).B_gradient_hessian(pts)
            np.testing.assert_allclose(Bf + Bu @ current, B, rtol=0, atol=1e-14 * np.abs(B).max())
            np.testing.assert_allclose(Gf + Gu @ current, G, rtol=0, atol=1e-14 * np.abs(G).max())
            np.testing.assert_allclose(Hf + Hu @ current, H, rtol=0, atol=1e-13 * np.abs(H).max())

    def test_present_field_is_fixed_plus_unit_fields_times_present_currents(self, rng):
        system = mixed_system()
        pts = points(rng)
        Bu, Gu = system.unit_fields(pts)
        Bf, Gf = system.fixed_field(pts)
        B, G = system.B_and_gradient(pts)
        np.testing.assert_allclose(Bf + Bu @ system.currents, B, atol=1e-14 * np.abs(B).max())
        np.testing.assert_allclose(Gf + Gu @ system.currents, G, atol=1e-14 * np.abs(G).max())

    def test_one_compiled_pass_per_channel(self, rng, monkeypatch):
        from coils.coaxial import CoaxialCoils

        system = presets.eight_coil_hemisphere()
        pts = points(rng, n=50)
        system.unit_fields(pts)  # build the unit channels
        calls = []
        run = CoaxialCoils._run

        def counting(self, pts, *args):
            calls.append(len(pts))
            return run(self, pts, *args)

        monkeypatch.setattr(CoaxialCoils, "_run", counting)
        system.unit_fields(pts)
        assert calls == [50] * 8  # as many passes as one evaluation of the system
        calls.clear()
        system.with_currents(np.ones(8)).B_and_gradient(pts)
        assert calls == [50] * 8

    def test_no_channels(self, rng):
        system = coils.CoilSystem([coils.UniformField((0, 1e-3, 0))])
        Bu, Gu = system.unit_fields(points(rng, n=4))
        assert Bu.shape == (4, 3, 0)
        assert Gu.shape == (4, 3, 3, 0)
        assert system.currents.shape == (0,)
        with pytest.raises(ValueError, match="no current channels"):
            system.currents_for(B=(0, 1e-3, 0))


# -- agreement with magpylib ---------------------------------------------------------------------
@pytest.mark.parametrize("name", PRESETS)
def test_preset_unit_fields_against_magpylib(name, rng):
    system = getattr(presets, name)()
    pts = points(rng, n=12, half=0.04)
    Bu, Gu = system.unit_fields(pts)
    for j, loops in enumerate(documented_geometry(name)):
        ref = magpylib_loops(loops)
        Bm = magpylib_B(ref, pts)
        np.testing.assert_allclose(Bu[..., j], Bm, rtol=0, atol=1e-13 * np.abs(Bm).max())
        Gm = magpylib_gradient(ref, pts, step=1e-4 * 0.06)
        np.testing.assert_allclose(Gu[..., j], Gm, rtol=0, atol=1e-9 * np.abs(Gm).max())


# -- the presets at their centres ----------------------------------------------------------------
class TestPresetCentres:
    def test_three_axis_helmholtz_centre_fields(self):
        system = presets.three_axis_helmholtz()
        Bu, Gu = system.unit_fields(system.center)
        expected = HELMHOLTZ * mu_0 * 200 / np.array([0.10, 0.14, 0.18])
        np.testing.assert_allclose(Bu[0], np.diag(expected), rtol=1e-14, atol=1e-20)
        assert np.abs(Gu).max() < 1e-12 * expected.max() / 0.1
        # a chosen field direction at 5 mT from the three pairs
        target = 5e-3 * np.array([0.6, -0.0, 0.8])
        current = system.currents_for(B=target)
        np.testing.assert_allclose(current, target / expected, rtol=1e-13)

    @pytest.mark.parametrize("axis", ["y", "x"])
    def test_helmholtz_maxwell_centre_gradient(self, axis):
        system = presets.helmholtz_maxwell(maxwell_axis=axis)
        Bu, Gu = system.unit_fields(system.center)
        g = MAXWELL * mu_0 * 500 / 0.24**2
        expected = coils.maxwell_gradient(g, "xyz".index(axis))
        np.testing.assert_allclose(Gu[0, :, :, 3], expected, rtol=0, atol=1e-13 * g)
        assert np.linalg.norm(Bu[0, :, 3]) < 1e-14 * g * 0.24
        assert g * 15.0 == pytest.approx(0.1049, abs=1e-4)  # documented

    def test_hemisphere_coils_on_axis_closed_form(self):
        system = presets.eight_coil_hemisphere()
        Bu, Gu = system.unit_fields(system.center)
        a, d, N = 0.06, 0.2, 600
        b = mu_0 * N * a**2 / (2 * (a**2 + d**2) ** 1.5)
        dbdz = -1.5 * mu_0 * N * a**2 * d / (a**2 + d**2) ** 2.5
        for j, ch in enumerate(system.channels):
            n = ch.axis
            np.testing.assert_allclose(Bu[0, :, j], b * n, rtol=1e-13, atol=1e-16 * b)
            expected = dbdz * (np.outer(n, n) - 0.5 * (np.eye(3) - np.outer(n, n)))
            np.testing.assert_allclose(Gu[0, :, :, j], expected, rtol=0, atol=1e-13 * abs(dbdz))
            # the documented geometry: on the lower hemisphere, pointing at the centre
            assert np.linalg.norm(ch.center - system.center) == pytest.approx(d, rel=1e-15)
            assert ch.center[2] <= 1e-15
            np.testing.assert_allclose(n, -ch.center / d, atol=1e-15)
        assert b * 20 == pytest.approx(2.98e-3, rel=1e-3)  # documented: 3.0 mT per coil

    def test_hemisphere_controls_field_and_gradient(self):
        system = presets.eight_coil_hemisphere()
        Bu, Gu = system.unit_fields(system.center)
        A = np.vstack([Bu[0], 0.06 * Gu[0].reshape(9, 8)])
        s = np.linalg.svd(A, compute_uv=False)
        assert s[-1] > 0.05 * s[0]  # 8 independent components, well conditioned

    @pytest.mark.parametrize("name", PRESETS)
    def test_wires_keep_clear_of_each_other(self, name):
        system = getattr(presets, name)()
        t = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
        rings = []
        for loops in documented_geometry(name):
            pts = []
            for centre, axis, radius, _ in loops:
                axis = np.asarray(axis) / np.linalg.norm(axis)
                u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
                u /= np.linalg.norm(u)
                v = np.cross(axis, u)
                pts.append(centre + radius * (np.outer(np.cos(t), u) + np.outer(np.sin(t), v)))
            rings.append(np.vstack(pts))
        from scipy.spatial import cKDTree

        # room for each channel's square winding of its turns of 2 mm wire at pi/4 fill:
        # the ring centre-lines must be farther apart than the half-diagonals of both
        half_diagonal = [math.sqrt(ch.turns * 2e-3**2) / math.sqrt(2) for ch in system.channels]
        gaps = {}
        for i, j in itertools.combinations(range(len(rings)), 2):
            gaps[i, j] = cKDTree(rings[j]).query(rings[i])[0].min()
            assert gaps[i, j] > half_diagonal[i] + half_diagonal[j], (i, j)
        gap = min(gaps.values())
        if name != "eight_coil_hemisphere":
            assert gap == pytest.approx(math.sqrt(5) / 2 * 0.04, rel=1e-4)  # documented

    def test_presets_limits_names_and_zero_currents(self):
        for name, m in zip(PRESETS, (3, 4, 8), strict=True):
            system = getattr(presets, name)()
            assert system.currents.tolist() == [0.0] * m
            assert len(system.names) == m == len(set(system.names))
        np.testing.assert_array_equal(presets.helmholtz_maxwell().max_current, [10, 10, 10, 15])
        np.testing.assert_array_equal(presets.eight_coil_hemisphere().max_current, [20] * 8)


# -- copper power --------------------------------------------------------------------------------
class TestPower:
    def test_against_hand_computation(self):
        system = presets.three_axis_helmholtz()
        current = np.array([3.0, -4.0, 5.0])
        area = math.pi * (2e-3) ** 2 / 4
        R = [COPPER_RESISTIVITY * 2 * 200 * 2 * math.pi * r / area for r in (0.10, 0.14, 0.18)]
        assert system.resistance == pytest.approx(R, rel=1e-14)
        hand = sum(r * i**2 for r, i in zip(R, current, strict=True))
        assert system.power(current) == pytest.approx(hand, rel=1e-14)
        # rounded by hand: 1.3793, 1.9310, 2.4827 ohm -> 12.41 + 30.90 + 62.07 W
        assert system.power(current) == pytest.approx(105.38, abs=0.01)

    def test_winding_fill_and_explicit_resistance(self):
        pair = coils.HelmholtzPair(0.1, 300, 1.0, winding=(0.02, 0.03))
        copper = math.pi / 4 * 0.02 * 0.03 / 300  # per turn, m^2
        assert pair.resistance == pytest.approx(
            COPPER_RESISTIVITY * 2 * 300 * 2 * math.pi * 0.1 / copper, rel=1e-14
        )
        coil = coils.Coil(0.1, 300, 2.0, resistance=4.5)
        system = coils.CoilSystem([pair, coil])
        assert system.power() == pytest.approx(pair.resistance * 1.0 + 4.5 * 4.0, rel=1e-15)

    def test_agrees_with_winding_power(self):
        from coils.design import winding_power

        pair = coils.MaxwellPair(0.12, 150, 2.5, wire_diameter=1.2e-3)
        system = coils.CoilSystem([pair])
        assert system.power() == pytest.approx(winding_power(pair, 1.2e-3).power, rel=1e-14)

    def test_many_current_vectors_at_once(self, rng):
        system = presets.eight_coil_hemisphere()
        current = rng.uniform(-20, 20, (5, 8))
        np.testing.assert_allclose(
            system.power(current), [system.power(c) for c in current], rtol=1e-15
        )

    def test_unknown_resistance_is_an_error(self):
        system = coils.CoilSystem(
            [coils.HelmholtzPair(0.1, 10, 1.0, wire_diameter=1e-3), coils.Coil(0.1, 10, 1.0)]
        )
        with pytest.raises(ValueError, match=r"channels 1 \(Coil axis \+z\) have no resistance"):
            system.power([1.0, 1.0])


# -- currents for a target -----------------------------------------------------------------------
def centre_matrix(system, at=None):
    at = system.center if at is None else at
    Bu, Gu = system.unit_fields(at)
    return Bu[0], Gu[0]


def random_gradient(rng, size):
    G = rng.normal(size=(3, 3))
    G = G + G.T
    return size * (G - np.trace(G) / 3 * np.eye(3)) / np.abs(G).max()


class TestCurrentsFor:
    def test_reproduces_field_and_gradient(self, rng):
        system = presets.eight_coil_hemisphere()
        B = rng.normal(size=3) * 2e-3
        G = random_gradient(rng, 0.02)
        current = system.currents_for(B=B, gradient=G)
        made = system.with_currents(current)
        Bm, Gm = made.B_and_gradient(system.center)
        np.testing.assert_allclose(Bm[0], B, rtol=0, atol=1e-9 * np.abs(B).max())
        np.testing.assert_allclose(Gm[0], G, rtol=0, atol=1e-9 * np.abs(G).max())

    def test_at_another_point_with_fixed_parts(self):
        earth = coils.UniformField((2e-5, 0.0, -4.5e-5))
        system = coils.CoilSystem([*presets.helmholtz_maxwell().parts, earth])
        at = np.array([0.01, -0.02, 0.005])
        target = np.array([1e-3, 4e-3, -2e-3])
        current = system.currents_for(B=target, at=at)
        np.testing.assert_allclose(
            system.with_currents(current).B(at)[0], target, rtol=0, atol=1e-12
        )

    def test_minimum_power_against_scipy(self, rng):
        from scipy.optimize import minimize

        system = presets.eight_coil_hemisphere()
        Bu, Gu = centre_matrix(system)
        R = system.resistance * np.linspace(0.8, 1.3, 8)  # unequal weights
        target = np.array([1e-3, -2e-3, 1.5e-3])
        current = system.currents_for(B=target, weights=R)
        res = minimize(
            lambda x: np.sum(R * x**2),
            np.zeros(8),
            jac=lambda x: 2 * R * x,
            constraints=[{"type": "eq", "fun": lambda x: 1e3 * (Bu @ x - target)}],
            method="SLSQP",
            options={"ftol": 1e-14, "maxiter": 500},
        )
        assert res.success
        np.testing.assert_allclose(current, res.x, rtol=0, atol=1e-6 * np.abs(res.x).max())
        # KKT: R I lies in the row space of the constraint (no cheaper direction along it)
        lam = np.linalg.lstsq(Bu.T, R * current, rcond=None)[0]
        np.testing.assert_allclose(Bu.T @ lam, R * current, atol=1e-10 * np.abs(R * current).max())
        # default weights: the resistances, i.e. the copper power
        plain = system.currents_for(B=target)
        assert system.power(plain) <= system.power(current)

    def test_two_coaxial_pairs_share_by_the_closed_form(self):
        # min R1 I1^2 + R2 I2^2 with a1 I1 + a2 I2 = b  =>  I_j = b (a_j / R_j) / sum(a^2 / R)
        p1 = coils.HelmholtzPair(0.10, 100, 0.0, axis="y", resistance=1.0)
        p2 = coils.HelmholtzPair(0.16, 250, 0.0, axis="y", resistance=3.0)
        system = coils.CoilSystem([p1, p2])
        a = HELMHOLTZ * mu_0 * np.array([100 / 0.10, 250 / 0.16])
        R = np.array([1.0, 3.0])
        b = 7e-3
        expected = b * (a / R) / np.sum(a**2 / R)
        np.testing.assert_allclose(system.currents_for(B=(0, b, 0)), expected, rtol=1e-12)
        # equal weights: proportional to a
        np.testing.assert_allclose(
            system.currents_for(B=(0, b, 0), weights=[1, 1]), b * a / np.sum(a**2), rtol=1e-12
        )

    def test_active_limits_against_brute_force(self):
        system = presets.eight_coil_hemisphere()
        Bu, _ = centre_matrix(system)
        R, lim = system.resistance, system.max_current
        direction = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
        target = 8.5e-3 * direction  # the unlimited minimum-power currents exceed 20 A
        unlimited = system.currents_for(B=target, weights=R)  # no error: feasible
        free = system.with_limits(np.inf)
        assert np.abs(free.currents_for(B=target)).max() > 1.15 * 20
        assert np.all(np.abs(unlimited) <= lim)
        np.testing.assert_allclose(Bu @ unlimited, target, atol=1e-9 * 8.5e-3)
        # brute force: every assignment of each channel to free, +limit or -limit
        best, best_power = None, np.inf
        for state in itertools.product((0, 1, -1), repeat=8):
            state = np.array(state)
            fixed = state != 0
            x = np.where(fixed, state * lim, 0.0)
            rest = target - Bu[:, fixed] @ x[fixed]
            if np.any(~fixed):
                scale = 1 / np.sqrt(R[~fixed])
                y = np.linalg.pinv(Bu[:, ~fixed] * scale) @ rest
                x[~fixed] = scale * y
            if np.linalg.norm(Bu @ x - target) > 1e-9 * 8.5e-3 or np.any(np.abs(x) > lim + 1e-9):
                continue
            power = np.sum(R * x**2)
            if power < best_power:
                best, best_power = x, power
        np.testing.assert_allclose(unlimited, best, atol=1e-7 * 20)
        assert system.power(unlimited) == pytest.approx(best_power, rel=1e-9)

    def test_beyond_the_limits_gives_the_largest_fraction(self):
        system = presets.three_axis_helmholtz()  # unique currents: fraction = min(lim / |I|)
        target = np.array([30e-3, -5e-3, 12e-3])
        per_amp = HELMHOLTZ * mu_0 * 200 / np.array([0.10, 0.14, 0.18])
        fraction = np.min(10.0 / np.abs(target / per_amp))
        with pytest.raises(ValueError, match="exceeds the current limits") as err:
            system.currents_for(B=target)
        assert f"at most {100 * fraction:.4g} %" in str(err.value)
        assert "channel 0 (x Helmholtz), limit 10 A" in str(err.value)
        # exactly at the limit is allowed
        at_limit = fraction * target
        current = system.currents_for(B=at_limit)
        assert np.abs(current).max() == pytest.approx(10.0, rel=1e-9)
        assert np.all(np.abs(current) <= 10.0)

    def test_what_the_system_cannot_make(self):
        helmholtz = presets.three_axis_helmholtz()
        with pytest.raises(ValueError, match=r"cannot make this target at \(0, 0, 0\) mm: its 3 "):
            helmholtz.currents_for(gradient=coils.maxwell_gradient(0.1))
        # a uniform field with zero gradient is what Helmholtz pairs make
        current = helmholtz.currents_for(B=(1e-3, 0, 0), gradient=np.zeros((3, 3)))
        assert current[0] > 0
        hm = presets.helmholtz_maxwell()
        g = coils.maxwell_gradient(0.05, 1)
        current = hm.currents_for(B=(0, 2e-3, 0), gradient=g)
        assert current[3] == pytest.approx(0.05 / (MAXWELL * mu_0 * 500 / 0.24**2), rel=1e-9)
        with pytest.raises(ValueError, match="misses B by .* and the gradient by"):
            hm.currents_for(B=(0, 2e-3, 0), gradient=coils.maxwell_gradient(0.05, 0))
        # a single coil: only fields along its axis at a point on its axis
        coil = coils.CoilSystem([coils.Coil(0.05, 100, 0.0, axis="z", center=(0, 0, -0.1))])
        assert coil.currents_for(B=(0, 0, 1e-4), at=(0, 0, 0))[0] > 0
        with pytest.raises(ValueError, match="make 1 of the 3"):
            coil.currents_for(B=(1e-4, 0, 0), at=(0, 0, 0))


# -- bad input -----------------------------------------------------------------------------------
class TestBadInput:
    @pytest.mark.parametrize(
        ("value", "match"),
        [
            ([1.0, 2.0], r"currents must have shape \(3,\); got \(2,\)"),
            ([1.0, np.nan, 0.0], "currents must be finite"),
            ([1.0, np.inf, 0.0], "currents must be finite"),
            ("1, 2, 3", "currents must be real numbers"),
            ([True, 0.0, 0.0], "currents must be real numbers"),
            (np.ones((3, 1)), r"currents must have shape \(3,\)"),
        ],
    )
    def test_bad_currents(self, value, match):
        system = presets.three_axis_helmholtz()
        with pytest.raises(ValueError, match=match):
            system.with_currents(value)

    def test_over_the_limit_names_the_channel(self):
        system = presets.eight_coil_hemisphere()
        current = np.zeros(8)
        current[5] = -20.5
        with pytest.raises(
            ValueError,
            match=r"currents\[5\] = -20.5 A exceeds max_current\[5\] = 20 A \(channel 5: coil "
            r"polar 45 deg azimuth 135 deg\)",
        ):
            system.with_currents(current)
        current[5] = -20.0  # the limit itself is allowed
        assert system.with_currents(current).currents[5] == -20.0

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"max_current": 0.0}, r"max_current\[0\] must be positive"),
            ({"max_current": [1.0, -1.0]}, r"max_current\[1\] must be positive"),
            ({"max_current": [1.0, np.nan]}, r"max_current\[1\] must be positive"),
            ({"max_current": [1.0, 2.0, 3.0]}, r"max_current must be a scalar or have shape \(2,"),
            ({"max_current": "10 A"}, "max_current must be a scalar or real numbers"),
            ({"names": ["a"]}, "names must be a sequence of 2 strings"),
            ({"names": "ab"}, "names must be a sequence of 2 strings"),
            ({"max_current": 1.0}, r"channel 1 \(MaxwellPair axis \+y\) carries 2 A, above"),
        ],
    )
    def test_bad_system_parameters(self, kwargs, match):
        parts = [coils.HelmholtzPair(0.1, 10, 1.0), coils.MaxwellPair(0.1, 10, 2.0)]
        with pytest.raises(ValueError, match=match):
            coils.CoilSystem(parts, **kwargs)

    def test_unit_fields_bad_points_and_windings(self):
        system = presets.three_axis_helmholtz()
        with pytest.raises(ValueError, match=r"points must have shape \(n, 3\); got \(2,\)"):
            system.unit_fields([0.0, 0.0])
        with pytest.raises(ValueError, match="points must be finite"):
            system.unit_fields([[0.0, np.nan, 0.0]])
        with pytest.raises(ValueError, match="hessian must be True or False"):
            system.unit_fields([0.0, 0.0, 0.0], hessian="yes")
        with pytest.raises(ValueError, match="point 1 lies on a coil winding"):
            system.unit_fields([[0.0, 0.0, 0.0], [0.05, 0.1, 0.0]])

    def test_bad_power_arguments(self):
        system = presets.three_axis_helmholtz()
        with pytest.raises(ValueError, match=r"currents must have shape \(3,\) or \(p, 3\)"):
            system.power([1.0, 2.0])
        with pytest.raises(ValueError, match="currents must be finite"):
            system.power([1.0, np.inf, 2.0])

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({}, "give a target"),
            ({"B": (0, 1e-3)}, r"B must have shape \(3,\)"),
            ({"B": (0, np.nan, 0)}, "B must be finite"),
            ({"gradient": np.eye(3)}, "gradient must be symmetric and traceless"),
            ({"gradient": [[0, 1, 0], [0, 0, 0], [0, 0, 0]]}, "symmetric and traceless"),
            ({"gradient": np.zeros(3)}, r"gradient must have shape \(3, 3\)"),
            ({"B": (0, 1e-3, 0), "at": (0, 0)}, r"at must have shape \(3,\)"),
            ({"B": (0, 1e-3, 0), "weights": [1, 0, 1]}, "weights must be positive"),
            ({"B": (0, 1e-3, 0), "weights": [1, 1]}, r"weights must have shape \(3,\)"),
            ({"B": (0, 1e-3, 0), "at": (0.05, 0.1, 0)}, "lies on a coil winding"),
        ],
    )
    def test_bad_currents_for_arguments(self, kwargs, match):
        with pytest.raises(ValueError, match=match):
            presets.three_axis_helmholtz().currents_for(**kwargs)

    @pytest.mark.parametrize(
        ("make", "match"),
        [
            (lambda: coils.Coil(0.1, 10, 1.0, resistance=1.0, wire_diameter=1e-3), "not both"),
            (lambda: coils.Coil(0.1, 10, 1.0, resistance=-1.0), "resistance must be positive"),
            (lambda: coils.HelmholtzPair(0.1, 10, 1.0, wire_diameter=0), "wire_diameter must be"),
            (
                lambda: coils.HelmholtzPair(
                    0.1, 1000, 1.0, winding=(0.01, 0.01), wire_diameter=1e-3
                ),
                "do not fit",
            ),
            (lambda: coils.Coil(0.1, 10, 1.0).with_current(np.nan), "current must be finite"),
            (lambda: presets.eight_coil_hemisphere(radius=0.3), "radius must be below distance"),
            (lambda: presets.helmholtz_maxwell(maxwell_radius=0.15), "maxwell_radius must exceed"),
            (lambda: presets.three_axis_helmholtz(radii=(0.1, 0.2)), "radii must be a scalar or"),
            (lambda: presets.three_axis_helmholtz(turns=(1, 0, 1)), r"turns\[1\] must be positive"),
            (lambda: presets.three_axis_helmholtz(max_current=-1), r"max_current\[0\] must be"),
        ],
    )
    def test_bad_coil_and_preset_parameters(self, make, match):
        with pytest.raises(ValueError, match=match):
            make()
