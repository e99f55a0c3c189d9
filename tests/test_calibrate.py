"""Calibration from data (coilrod.calibrate), grouped by property.

* recovery: parameters used to make synthetic data by independent solve_rod runs come back
  (to round-off without noise; within three standard errors with noise, whose size is checked
  against a Jacobian made by central differences);
* the Jacobian: the fit's exact Jacobian against central differences of independent solves,
  and the E / |M| proportionality behind the identifiability check;
* identifiability: E and |M| together, a parameter with no effect, the antiparallel buckling
  case without an imperfection;
* failures: a model that cannot be solved (at the start; at a trial point), an unconverged fit;
* bad input: every argument, with a message naming it.

The rod is the Zhao et al. (2019) beam (L 17.2 mm, 5 mm x 0.84 mm, |M| = 114 kA/m).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.constants import mu_0

import coilrod
import coils
from coilrod import (
    ConvergenceError,
    IdentifiabilityError,
    Magnetization,
    Rectangle,
    Rod,
    StabilityWarning,
    calibrate,
    solve_rod,
)
from coilrod.design import calibrate as calibrate_module
from coilrod.design.calibrate import UnstableStateError, _check_rank

L = 17.2e-3
E_TRUE = 950e3
M_TRUE = 0.143 / mu_0
SECTION = Rectangle(width=5e-3, thickness=0.84e-3)
B_90 = np.array([0.0, 2e-3, 4e-3, 7e-3, 10e-3, 15e-3, 25e-3, 40e-3])  # T, with the zero field


def _rod(E=E_TRUE, M=M_TRUE, angle=0.0):
    return Rod(L, E, SECTION, Magnetization(M, angle))


def _rotated(B, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * B[0] - s * B[1], s * B[0] + c * B[1], B[2]])


def _along(direction, magnitudes):
    return np.asarray(magnitudes)[:, None] * np.asarray(direction, float)[None]


def _tips(rod, direction, magnitudes, angle=0.0, output="tip_y"):
    """Independent reference: one solve_rod per field (from zero), tolerance 1e-12."""
    out = []
    for b in magnitudes:
        if b == 0:
            out.append({"tip_x": rod.length, "tip_y": 0.0, "tip_angle": 0.0}[output])
            continue
        field = coils.UniformField(B=_rotated(b * np.asarray(direction, float), angle))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = solve_rod(rod, field, [1.0], tol=1e-12)
        out.append(
            {"tip_x": res.tip[0, 0], "tip_y": res.tip[0, 1], "tip_angle": res.tip_angle[0]}[output]
        )
    return np.array(out)


@pytest.fixture(scope="module")
def data_90():
    """(fields (k, 3), tip y (k,)) of the true rod, field along +y."""
    return _along((0, 1, 0), B_90), _tips(_rod(), (0, 1, 0), B_90)


# -- recovery -----------------------------------------------------------------------------------
class TestRecovery:
    def test_youngs_modulus_recovered_exactly(self, data_90):
        fields, tip = data_90
        cal = calibrate(_rod(E=2 * E_TRUE), fields, tip, solve_options={"tol": 1e-12})
        assert cal.success
        assert cal.values["youngs_modulus"] == pytest.approx(E_TRUE, rel=1e-8)
        assert cal.rod.youngs_modulus == cal.values["youngs_modulus"]
        assert np.abs(cal.residuals).max() < 1e-10 * L
        np.testing.assert_allclose(cal.model, tip, rtol=0, atol=1e-10 * L)
        assert cal.residuals.shape == (B_90.size,)
        assert cal.model[0] == 0.0
        assert cal.nfev >= cal.njev >= 1
        assert cal.solves == cal.nfev

    def test_magnitude_recovered_exactly(self, data_90):
        fields, tip = data_90
        cal = calibrate(_rod(M=0.5 * M_TRUE), fields, tip, fit="magnitude")
        assert cal.values["magnitude"] == pytest.approx(M_TRUE, rel=1e-8)
        assert cal.remanence == pytest.approx(0.143, rel=1e-8)
        assert cal.rod.youngs_modulus == E_TRUE  # fixed

    def test_modulus_and_misalignment_recovered(self):
        angle = 0.08
        tip = _tips(_rod(), (0, 1, 0), B_90, angle=angle)
        cal = calibrate(
            _rod(E=0.6 * E_TRUE),
            _along((0, 1, 0), B_90),
            tip,
            fit=("youngs_modulus", "field_angle"),
        )
        assert cal.values["youngs_modulus"] == pytest.approx(E_TRUE, rel=1e-8)
        assert cal.values["field_angle"] == pytest.approx(angle, rel=1e-8)
        assert cal.field_angle == cal.values["field_angle"]

    @pytest.mark.parametrize("output", ["tip_x", "tip_angle"])
    def test_other_outputs(self, output):
        tip = _tips(_rod(), (0, 1, 0), B_90, output=output)
        cal = calibrate(_rod(E=1.5 * E_TRUE), _along((0, 1, 0), B_90), tip, output=output)
        assert cal.values["youngs_modulus"] == pytest.approx(E_TRUE, rel=1e-8)

    def test_several_field_directions(self):
        """Fields at 90 and 135 degrees to M (two load paths, interleaved and unsorted)."""
        d135 = (-np.sqrt(0.5), np.sqrt(0.5), 0.0)
        b = np.array([12e-3, 3e-3, 6e-3])
        fields = np.vstack([_along((0, 1, 0), b), _along(d135, b)])[[0, 3, 1, 4, 2, 5]]
        tip = np.r_[_tips(_rod(), (0, 1, 0), b), _tips(_rod(), d135, b)][[0, 3, 1, 4, 2, 5]]
        cal = calibrate(_rod(E=3 * E_TRUE), fields, tip)
        assert cal.values["youngs_modulus"] == pytest.approx(E_TRUE, rel=1e-8)
        assert cal.solves == 2 * cal.nfev
        curves = cal.model_curve(samples=5)
        assert len(curves) == 2
        for direction, magnitudes, values in curves:
            rows = np.flatnonzero(
                np.abs(fields @ direction - np.linalg.norm(fields, axis=1)) < 1e-15
            )
            assert magnitudes[-1] == pytest.approx(12e-3)
            assert values[-1] == pytest.approx(tip[rows[0]], abs=1e-9 * L)  # 12 mT is first

    def test_noise_true_value_within_three_standard_errors(self, data_90, rng):
        fields, tip = data_90
        noise = 0.01 * L
        for _ in range(4):
            measured = tip + noise * rng.normal(size=tip.size)
            cal = calibrate(_rod(), fields, measured)
            E, se = cal.values["youngs_modulus"], cal.standard_errors["youngs_modulus"]
            assert abs(E - E_TRUE) < 3 * se
            # the standard error from a central-difference Jacobian of independent solves
            h = 1e-4 * E
            J = (_tips(_rod(E=E + h), (0, 1, 0), B_90) - _tips(_rod(E=E - h), (0, 1, 0), B_90)) / (
                2 * h
            )
            s2 = np.sum(cal.residuals**2) / (tip.size - 1)
            assert se == pytest.approx(np.sqrt(s2 / (J @ J)), rel=1e-5)
            # the cost from the residuals of a fresh solve at the fitted E (not cal.residuals)
            fresh = _tips(_rod(E=E), (0, 1, 0), B_90) - measured
            assert cal.cost == pytest.approx(0.5 * np.sum(fresh**2), rel=1e-6)

    def test_uniform_sigma_changes_nothing_but_the_cost(self, data_90, rng):
        fields, tip = data_90
        measured = tip + 0.01 * L * rng.normal(size=tip.size)
        plain = calibrate(_rod(), fields, measured)
        weighted = calibrate(_rod(), fields, measured, sigma=1e-4)
        assert weighted.values["youngs_modulus"] == pytest.approx(
            plain.values["youngs_modulus"], rel=1e-7
        )
        assert weighted.standard_errors["youngs_modulus"] == pytest.approx(
            plain.standard_errors["youngs_modulus"], rel=1e-5
        )
        assert weighted.cost == pytest.approx(plain.cost / 1e-8, rel=1e-6)
        np.testing.assert_array_equal(weighted.sigma, np.full(tip.size, 1e-4))

    def test_bounds_hold(self, data_90):
        fields, tip = data_90
        cal = calibrate(_rod(E=0.5 * E_TRUE), fields, tip, bounds={"youngs_modulus": (0, 8e5)})
        assert cal.values["youngs_modulus"] == pytest.approx(8e5, rel=1e-6)


# -- the Jacobian -------------------------------------------------------------------------------
class TestJacobian:
    def test_jacobian_matches_central_differences(self, data_90):
        fields, tip = data_90
        measured = tip * (1 + 0.03 * np.sin(np.arange(tip.size)))  # not at the truth
        cal = calibrate(
            _rod(), fields, measured, fit=("youngs_modulus", "field_angle"), field_angle=0.05
        )
        E, a = cal.values["youngs_modulus"], cal.values["field_angle"]
        hE, ha = 1e-4 * E, 1e-5
        dE = _tips(_rod(E=E + hE), (0, 1, 0), B_90, a) - _tips(_rod(E=E - hE), (0, 1, 0), B_90, a)
        da = _tips(_rod(E=E), (0, 1, 0), B_90, a + ha) - _tips(_rod(E=E), (0, 1, 0), B_90, a - ha)
        J = np.column_stack([dE / (2 * hE), da / (2 * ha)])
        np.testing.assert_allclose(cal.jacobian, J, rtol=1e-6, atol=1e-9 * np.abs(J).max())
        np.testing.assert_allclose(cal.model, _tips(cal.rod, (0, 1, 0), B_90, a), atol=1e-9 * L)

    def test_modulus_and_magnitude_columns_are_proportional(self, data_90):
        """dtip/dE = -(|M| / E) dtip/d|M|: lambda depends on |M| / E only (also by differences)."""
        fields, tip = data_90
        by_E = calibrate(_rod(), fields, tip, fit="youngs_modulus", max_nfev=1)
        by_M = calibrate(_rod(), fields, tip, fit="magnitude", max_nfev=1)
        np.testing.assert_allclose(
            by_E.jacobian[:, 0] * E_TRUE, -by_M.jacobian[:, 0] * M_TRUE, rtol=1e-9, atol=1e-16
        )
        h = 1e-4
        dM = _tips(_rod(M=M_TRUE * (1 + h)), (0, 1, 0), B_90) - _tips(
            _rod(M=M_TRUE * (1 - h)), (0, 1, 0), B_90
        )
        np.testing.assert_allclose(
            by_M.jacobian[:, 0] * M_TRUE, dM / (2 * h), rtol=1e-6, atol=1e-12
        )


# -- identifiability ----------------------------------------------------------------------------
class TestIdentifiability:
    def test_modulus_and_magnitude_together_raise(self, data_90):
        fields, tip = data_90
        with pytest.raises(IdentifiabilityError, match=r"\|M\| / E") as info:
            calibrate(_rod(), fields, tip, fit=("youngs_modulus", "magnitude"))
        assert isinstance(info.value, ValueError)
        assert "Br / mu0" in str(info.value)
        assert "lambda" in str(info.value)

    def test_magnitude_and_modulus_in_either_order_raise(self, data_90):
        fields, tip = data_90
        with pytest.raises(IdentifiabilityError, match="rank deficient"):
            calibrate(_rod(), fields, tip * 1.1, fit=("magnitude", "youngs_modulus"))

    def test_zero_column_and_dependent_columns(self):
        J = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
        with pytest.raises(IdentifiabilityError, match="field_angle has no effect"):
            _check_rank(J, ("youngs_modulus", "field_angle"), 1e-6, "here")
        J = np.array([[1.0, 2.0], [2.0, 4.0 + 1e-9], [3.0, 6.0]])
        with pytest.raises(IdentifiabilityError, match="Fix all but one"):
            _check_rank(J, ("youngs_modulus", "field_angle"), 1e-6, "here")
        _check_rank(J, ("youngs_modulus", "field_angle"), 1e-12, "here")  # accepted

    def test_all_zero_fields_raise(self):
        with pytest.raises(ValueError, match="all zero"):
            calibrate(_rod(), np.zeros((3, 3)), [0.0, 0.0, 0.0])

    def test_antiparallel_needs_an_imperfection(self):
        b = np.array([6e-3, 10e-3, 20e-3])  # all past buckling (about 3.8 mT here)
        fields = _along((-1, 0, 0), b)
        with (
            pytest.raises(UnstableStateError, match="field_angle"),
            pytest.warns(StabilityWarning, match="lost stability"),
        ):
            calibrate(_rod(), fields, 0.5 * L * np.ones(3))
        angle = -np.radians(1.0)
        tip = _tips(_rod(), (-1, 0, 0), b, angle=angle)
        assert np.all(tip > 0.3 * L)  # buckled to +y
        cal = calibrate(_rod(E=1.3 * E_TRUE), fields, tip, field_angle=angle)
        assert cal.values["youngs_modulus"] == pytest.approx(E_TRUE, rel=1e-8)


# -- failures -----------------------------------------------------------------------------------
class TestFailures:
    def test_unsolvable_start_raises_with_context(self, data_90, monkeypatch):
        def failing(*args, **kwargs):
            raise ConvergenceError("stuck", reached=0.5, target=1.0, residual=3.0)

        monkeypatch.setattr(calibrate_module, "solve_rod", failing)
        fields, tip = data_90
        with pytest.raises(ConvergenceError, match=r"E = 950000 Pa.*stuck") as info:
            calibrate(_rod(), fields, tip)
        assert info.value.reached == pytest.approx(0.5 * B_90.max())
        assert info.value.target == pytest.approx(B_90.max())

    def test_failed_trial_point_is_rejected(self, data_90, monkeypatch):
        calls = []

        def second_fails(*args, **kwargs):
            calls.append(1)
            if len(calls) == 2:
                raise ConvergenceError("trial failed", reached=0.2, target=1.0)
            return solve_rod(*args, **kwargs)

        monkeypatch.setattr(calibrate_module, "solve_rod", second_fails)
        fields, tip = data_90
        cal = calibrate(_rod(E=2 * E_TRUE), fields, tip)
        assert len(cal.rejected) == 1
        assert "trial failed" in cal.rejected[0]
        assert cal.values["youngs_modulus"] == pytest.approx(E_TRUE, rel=1e-8)

    def test_unconverged_fit_warns(self, data_90):
        fields, tip = data_90
        with pytest.warns(RuntimeWarning, match="max_nfev = 1"):
            cal = calibrate(_rod(E=2 * E_TRUE), fields, tip, max_nfev=1)
        assert not cal.success


# -- result -------------------------------------------------------------------------------------
def test_result_summary_and_plot(data_90):
    import matplotlib.pyplot as plt

    fields, tip = data_90
    cal = calibrate(_rod(E=1.2 * E_TRUE), fields, tip * 1.02)
    text = repr(cal)
    assert "youngs_modulus" in text
    assert "rms residual" in text
    assert cal.dof == B_90.size - 1
    # from the residuals of a fresh solve at the fitted E, not from cal.residuals
    fresh = _tips(_rod(E=cal.values["youngs_modulus"]), (0, 1, 0), B_90) - tip * 1.02
    assert cal.rms == pytest.approx(np.sqrt(np.mean(fresh**2)), rel=1e-6)
    assert cal.correlation.shape == (1, 1)
    ax = cal.plot(per_length=True, samples=7)
    measured, curve = ax.lines
    np.testing.assert_allclose(measured.get_ydata(), tip * 1.02 / L)
    assert curve.get_xdata()[-1] == pytest.approx(40.0)
    assert curve.get_ydata()[-1] == pytest.approx(cal.model[-1] / L, rel=1e-9)
    plt.close("all")


def test_exported():
    assert coilrod.calibrate is calibrate
    assert "calibrate" in coilrod.__all__
    assert "Calibration" in coilrod.__all__


# -- bad input ----------------------------------------------------------------------------------
GOOD = {"fields": _along((0, 1, 0), [2e-3, 5e-3, 9e-3]), "measured": [1e-3, 3e-3, 5e-3]}
BAD = [
    ({"fields": np.zeros((3, 2))}, "fields must have shape"),
    ({"measured": [1e-3, 2e-3]}, r"measured must have one value per field, shape \(3,\)"),
    ({"measured": [1e-3, np.nan, 5e-3]}, "measured"),
    ({"fields": [[0, 1e-3, 0], [0, np.inf, 0], [0, 3e-3, 0]]}, "fields"),
    ({"fields": [[0, 1e-3, 1e-4], [0, 2e-3, 0], [0, 3e-3, 0]]}, "bending plane"),
    ({"fit": "poisson_ratio"}, "each entry of fit must be .youngs_modulus"),
    ({"fit": ()}, "at least one parameter"),
    ({"fit": 3}, "fit must be a parameter name"),
    ({"fit": ("youngs_modulus", "youngs_modulus")}, "twice"),
    ({"output": "tip_z"}, "output must be"),
    ({"sigma": -1.0}, "sigma must be positive"),
    ({"sigma": [1.0, 1.0]}, r"sigma must be a number or have shape \(3,\)"),
    ({"sigma": [1.0, np.nan, 1.0]}, "sigma"),
    ({"bounds": {"magnitude": (1, 2)}}, "not fitted"),
    ({"bounds": {"youngs_modulus": (2e6, 1e6)}}, "low < high"),
    ({"bounds": {"youngs_modulus": (2e6, 3e6)}}, "outside bounds"),
    ({"bounds": {"youngs_modulus": (-1.0, 3e6)}}, "non-negative"),
    ({"bounds": [(0, 1)]}, "bounds must be a dict"),
    ({"fit": ("youngs_modulus", "field_angle", "magnitude")}, "at least 4 data points"),
    ({"rank_tol": 0.0}, "rank_tol"),
    ({"tol": -1.0}, "tol"),
    ({"max_nfev": 0}, "max_nfev"),
    ({"field_angle": np.nan}, "field_angle"),
    ({"solve_options": {"stability": False}}, "solve_options may set"),
    # angles in degrees (h-brk): a tip more than a full turn from the clamp, a misalignment
    # beyond a full turn
    (
        {"output": "tip_angle", "measured": [5.0, 12.0, 20.0]},
        r"measured\[2\] = 20 rad .* full turn: tip_angle data are in radians \(degrees\?",
    ),
    ({"field_angle": 10.0}, r"field_angle = 10 rad is more than a full turn: it is in radians"),
]


@pytest.mark.parametrize(("change", "message"), BAD)
def test_bad_input(change, message):
    kwargs = {**GOOD, **change}
    fields, measured = kwargs.pop("fields"), kwargs.pop("measured")
    with pytest.raises(ValueError, match=message):
        calibrate(_rod(), fields, measured, **kwargs)


def test_tip_angles_within_a_turn_of_the_clamp_pass():
    # valid radians are not rejected: within a full turn of the clamp's angle, either way
    check = calibrate_module._check_radians
    check(np.array([-6.28, 0.0, 6.28]), "tip_angle", -6.28, {})
    check(np.array([8.0, -4.2]), "tip_angle", 0.0, {"clamp_angle": 2.0})
    check(np.array([20.0]), "tip_y", 0.0, {})  # not an angle (the length check is separate)
    with pytest.raises(ValueError, match=r"measured\[1\] = -4.3 rad .* clamp's angle 2 rad"):
        check(np.array([8.0, -4.3]), "tip_angle", 0.0, {"clamp_angle": 2.0})


def test_bad_rod_and_magnetization():
    with pytest.raises(ValueError, match="rod must be a coilrod.Rod"):
        calibrate("rod", GOOD["fields"], GOOD["measured"])
    segmented = dataclasses.replace(
        _rod(), magnetization=Magnetization.segments([L / 2, L / 2], [M_TRUE, M_TRUE / 2])
    )
    with pytest.raises(ValueError, match="constant magnetization"):
        calibrate(segmented, GOOD["fields"], GOOD["measured"], fit="magnitude")
    calibrate(segmented, GOOD["fields"], GOOD["measured"])  # E alone is fine
    with pytest.raises(ValueError, match="positive starting"):
        calibrate(_rod(M=-M_TRUE), GOOD["fields"], GOOD["measured"], fit="magnitude")
