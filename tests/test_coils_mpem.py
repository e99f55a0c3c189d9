"""Calibrated eMNS models (coils.MPEM): physics consistency, the shipped calibrations, bad input.

Cross-checks:

* every shipped calibration against a dipole sum written here from the YAML as parsed by
  PyYAML (independent of coils' parser and kernel), with the offset, at random currents;
* a single source against the closed forms on and across its axis;
* gradient and hessian against 4th-order central differences of B and of the gradient;
* curl B = div B = 0 (the gradient symmetric and traceless), the hessian symmetric;
* linearity: B(I) = B_offset + unit_fields @ I; currents_for makes its target;
* malformed files and a point on a source: ValueErrors naming file, coil, source and key.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import yaml

import coils
from coils import MPEM, presets
from coils.presets import CARDIOMAG_FILE, NAVION_FILE, OCTOMAG_FILE, _data_file

RNG = np.random.default_rng(21)
#: Points in the calibrated workspaces (a 10 cm cube around the centre), m.
POINTS = RNG.uniform(-0.05, 0.05, size=(12, 3))


def _reference(path, currents):
    """B (n, 3) at POINTS from the file, summed here: c (3 rh (d . rh) - d) / |r|^3."""
    doc = yaml.safe_load(_data_file(path).read_text())
    groups = [(doc[name], I) for name, I in zip(doc["Coil_List"], currents, strict=True)]
    if "Offset" in doc:
        groups.append((doc["Offset"], 1.0))
    out = np.zeros((len(POINTS), 3))
    for coil, current in groups:
        for src in coil["Source_List"]:
            s = coil[src]
            c = s["B_Coeff"][0] * current
            d = np.array(s["Source_Direction"], dtype=float)
            for k, x in enumerate(POINTS):
                r = x - np.array(s["Source_Position"], dtype=float)
                dist = np.sqrt(r @ r)
                rh = r / dist
                out[k] += c * (3 * rh * (d @ rh) - d) / dist**3
    return out


def _fd(f, x, h):
    """4th-order central difference of f (n, ...) along each axis: shape (..., 3)."""
    cols = []
    for e in np.eye(3):
        cols.append(
            (-f(x + 2 * h * e) + 8 * f(x + h * e) - 8 * f(x - h * e) + f(x - 2 * h * e)) / (12 * h)
        )
    return np.stack(cols, axis=-1)


MODELS = {
    "cardiomag": (presets.cardiomag, CARDIOMAG_FILE),
    "navion": (presets.navion, NAVION_FILE),
    "octomag": (lambda: presets.octomag(max_current=10.0), OCTOMAG_FILE),
}


@functools.cache
def _model(name: str) -> MPEM:
    """The shipped model ``name`` at its defaults, read once (models are immutable; reading
    CardioMag's file costs ~0.2 s, and the reader is checked against PyYAML above)."""
    return MODELS[name][0]()


# -- physics consistency ------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(MODELS))
def test_shipped_models_match_an_independent_dipole_sum(name):
    path = MODELS[name][1]
    model = _model(name)
    currents = RNG.uniform(-1, 1, len(model.channels)) * 5.0
    driven = model.with_currents(currents)
    ref = _reference(path, currents)
    B = driven.B(POINTS)
    assert np.abs(B - ref).max() <= 1e-13 * np.abs(ref).max()
    # linear in the currents, the offset fixed
    Bu, Gu = model.unit_fields(POINTS)
    Bf, Gf = model.fixed_field(POINTS)
    np.testing.assert_allclose(Bf + Bu @ currents, B, rtol=0, atol=1e-14 * np.abs(B).max())
    np.testing.assert_allclose(
        Gf + Gu @ currents, driven.gradient(POINTS), rtol=0, atol=1e-13 * np.abs(Gu).max()
    )


def test_blocked_kernel_equals_the_pointwise_one():
    """From 64 points on, B and gradient take the vectorised kernel (sources outer, points in
    blocks): the same sums as the per-point kernel (used below 64 points and for hessians), and
    a point on a source among many is named as well."""
    model = _model("cardiomag").with_currents(np.linspace(-20, 20, 8))
    X = RNG.uniform(-0.08, 0.08, size=(300, 3))
    B, G = model.B_and_gradient(X)  # blocked
    parts = [model.B_and_gradient(X[k : k + 50]) for k in range(0, 300, 50)]  # pointwise
    Bp, Gp = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
    assert np.abs(B - Bp).max() <= 1e-14 * np.abs(B).max()
    assert np.abs(G - Gp).max() <= 1e-14 * np.abs(G).max()
    np.testing.assert_array_equal(model.B(X), B)
    X[200] = model.positions[10]  # (beyond the workspace: checked without it)
    with pytest.raises(ValueError, match=r"points\[200\].*on source 2 of Coil_1"):
        model.replace(workspace=None).gradient(X)


def test_cardiomag_has_an_offset_field():
    """The CardioMag file's Offset sources: a current-independent field at the centre."""
    model = _model("cardiomag")
    B0 = model.B([0.0, 0.0, 0.0])[0]
    assert 1e-4 < np.linalg.norm(B0) < 1e-2  # the remanence of the cores: about 1.5 mT
    assert np.abs(_model("navion").B([0.0, 0.0, 0.0])).max() == 0.0


def test_single_source_closed_forms():
    """On the axis B = 2 c / z^3 d and dBz/dz = -6 c / z^4; across it B = -c / rho^3 d."""
    c, z = 3e-6, 0.07
    model = MPEM([([[0.0, 0.0, 0.0]], [[0.0, 0.0, c]])], currents=[1.0])
    B, G = model.B_and_gradient([[0.0, 0.0, z], [z, 0.0, 0.0]])
    np.testing.assert_allclose(B[0], [0.0, 0.0, 2 * c / z**3], rtol=1e-15, atol=0)
    np.testing.assert_allclose(B[1], [0.0, 0.0, -c / z**3], rtol=1e-15, atol=1e-30)
    assert G[0, 2, 2] == pytest.approx(-6 * c / z**4, rel=1e-15)
    assert G[0, 0, 0] == pytest.approx(3 * c / z**4, rel=1e-15)  # div B = 0


@pytest.mark.parametrize("name", ["cardiomag", "navion"])
def test_gradient_and_hessian_match_finite_differences(name):
    model = _model(name)
    model = model.with_currents(RNG.uniform(-1, 1, len(model.channels)) * 10.0)
    x = POINTS[:4]
    B, G, H = model.B_gradient_hessian(x)
    h = 1e-3
    G_fd = _fd(model.B, x, h)
    H_fd = _fd(model.gradient, x, h)
    assert np.abs(G - G_fd).max() <= 1e-8 * np.abs(G).max()
    assert np.abs(H - H_fd).max() <= 1e-8 * np.abs(H).max()
    np.testing.assert_array_equal(model.gradient(x), G)
    np.testing.assert_array_equal(model.hessian(x), H)


@pytest.mark.parametrize("name", list(MODELS))
def test_curl_and_divergence_free(name):
    model = _model(name)
    model = model.with_currents(np.linspace(-1, 1, len(model.channels)))
    _, G, H = model.B_gradient_hessian(POINTS)
    # to rounding of the sources' terms (Navion's nearly cancelling pairs: 1e-13 of the sum)
    scale = 1e2 * np.abs(G).max()
    assert np.abs(G - G.transpose(0, 2, 1)).max() <= 1e-14 * scale  # curl B = 0
    assert np.abs(np.trace(G, axis1=1, axis2=2)).max() <= 1e-14 * scale  # div B = 0
    hs = 1e2 * np.abs(H).max()
    assert np.abs(H - H.transpose(0, 2, 1, 3)).max() <= 1e-14 * hs
    assert np.abs(H - H.transpose(0, 1, 3, 2)).max() <= 1e-14 * hs
    assert np.abs(np.einsum("kiil->kl", H)).max() <= 1e-14 * hs


def test_unit_fields_hessian_per_ampere():
    model = _model("navion")
    Bu, Gu, Hu = model.unit_fields(POINTS[:3], hessian=True)
    I = np.array([3.0, -2.0, 1.0])
    np.testing.assert_allclose(
        Hu @ I, model.with_currents(I).hessian(POINTS[:3]), rtol=0, atol=1e-12 * np.abs(Hu).max()
    )


# -- currents for a target ----------------------------------------------------------------------
def test_currents_for_field_and_gradient_on_cardiomag():
    """Eight coils make 3 field + 5 gradient components at the centre, the offset included."""
    model = _model("cardiomag")
    target_B = np.array([5e-3, -3e-3, 4e-3])
    target_G = np.array([[0.05, 0.02, 0.0], [0.02, -0.1, 0.01], [0.0, 0.01, 0.05]])
    I = model.currents_for(B=target_B, gradient=target_G)
    B, G = model.with_currents(I).B_and_gradient([0.0, 0.0, 0.0])
    np.testing.assert_allclose(B[0], target_B, rtol=0, atol=1e-9 * 5e-3)
    np.testing.assert_allclose(G[0], target_G, rtol=0, atol=1e-9 * 0.1)


def test_currents_for_tells_what_is_missing():
    with pytest.raises(ValueError, match="cannot make this target.*3 coils make 3 of the 8"):
        _model("navion").currents_for(B=(0, 0, 1e-3), gradient=np.diag([0.1, 0.1, -0.2]))
    with pytest.raises(ValueError, match="exceeds the current limits.*Coil_"):
        _model("navion").currents_for(B=(0.0, 0.0, 1.0))


def test_current_limits():
    assert _model("cardiomag").max_current.tolist() == [20.0] * 8
    assert _model("navion").max_current.tolist() == [35.0] * 3
    with pytest.raises(TypeError, match="max_current"):
        presets.octomag()
    with pytest.raises(ValueError, match=r"currents\[1\] = 40 A exceeds max_current\[1\] = 35"):
        _model("navion").with_currents([0.0, 40.0, 0.0])
    with pytest.raises(AttributeError, match="with_currents"):
        _model("navion").currents = np.zeros(3)


# -- bad input ------------------------------------------------------------------------------------
def test_point_on_a_source_is_named():
    model = _model("navion").replace(workspace=None)  # (the sources lie beyond it)
    on = model.positions[4]  # Coil_1, its second source
    with pytest.raises(ValueError, match=r"points\[1\].*on source 1 of Coil_1 \(model Navion"):
        model.with_currents([1.0, 1.0, 1.0]).B([[0.0, 0.0, 0.0], on])
    with pytest.raises(ValueError, match="on source 1 of Coil_1"):
        model.unit_fields(on)


GOOD = """
Coil_List: [Coil_0]
Coil_0:
  Source_List: [Src_0]
  Src_0:
    A_Coeff: ~
    B_Coeff: [1.0e-6]
    Source_Direction: [0.0, 0.0, 1.0]
    Source_Position: [0.0, 0.0, -0.2]
"""


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("Coil_List: [Coil_0]", "Coil_Lst: [Coil_0]", "missing key 'Coil_List'"),
        ("Coil_List: [Coil_0]", "Coil_List: [Coil_0, Coil_1]", "coil 'Coil_1' is in Coil_List"),
        ("    B_Coeff: [1.0e-6]\n", "", "Coil_0: Src_0: missing key 'B_Coeff'"),
        ("[0.0, 0.0, -0.2]", "[0.0, -0.2]", "Coil_0: Src_0: Source_Position must have 3"),
        ("[1.0e-6]", "[1.0e-6, 2.0e-6]", "Coil_0: Src_0: B_Coeff must have 1"),
        ("[0.0, 0.0, 1.0]", "[0.0, 0.6, 1.0]", "Coil_0: Src_0: Source_Direction must be a unit"),
        ("[0.0, 0.0, 1.0]", "[0.0, zero, 1.0]", "Coil_0: Src_0: Source_Direction must be 3 num"),
        ("A_Coeff: ~", "A_Coeff: [1.0]", "Coil_0: Src_0: A_Coeff is given.*only dipole"),
        ("Source_List: [Src_0]", "Source_List: [Src_0, Src_1]", "Coil_0: Src_1: listed"),
        ("Coil_List", "Saturation_Functions: {}\nCoil_List", "saturation functions are not"),
    ],
)
def test_malformed_files_are_named(tmp_path, old, new, message):
    path = tmp_path / "bad_model.yaml"
    assert old in GOOD
    path.write_text(GOOD.replace(old, new))
    with pytest.raises(ValueError, match="bad_model.yaml.*" + message):
        MPEM.from_yaml(path)


def test_good_file_reads(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text(GOOD)
    model = MPEM.from_yaml(path, max_current=2.0)
    assert model.channels == ("Coil_0",)
    B = model.with_currents([2.0]).B([0.0, 0.0, 0.0])[0]
    np.testing.assert_allclose(B, [0.0, 0.0, 2 * 2 * 1e-6 / 0.2**3], rtol=1e-15)
    with pytest.raises(ValueError, match="cannot read the MPEM file"):
        MPEM.from_yaml(tmp_path / "missing.yaml")


def test_dipole_kernels_compile_once_for_sealed_or_writable_arrays():
    # issue 19: a sealed (read-only) and a writable array are different layouts to numba, and
    # each would compile its own version of a kernel (seconds on CI's empty cache)
    from coils import dipoles

    rng = np.random.default_rng(5)
    pts, pos, mom = rng.normal(size=(70, 3)) + 4.0, rng.normal(size=(2, 3)), rng.normal(size=(2, 3))
    out = []
    for writeable in (True, False):
        p, q = pts.copy(), pos.copy()
        p.flags.writeable = q.flags.writeable = writeable
        B, G, H = np.zeros((70, 3)), np.zeros((70, 3, 3)), np.zeros((70, 3, 3, 3))
        dipoles.dipole_sum(p, q, mom, 0.0, B, G)  # the blocked B + gradient kernel
        dipoles.dipole_sum(p, q, mom, 0.0, H=H)  # the exact one
        out.append((B, G, H))
    for a, b in zip(*out, strict=True):
        assert np.array_equal(a, b)
    assert len(dipoles._FAST.signatures) == 1
    assert len(dipoles._KERNEL.signatures) == 1


def test_a_calibrated_model_refuses_points_far_outside_its_workspace():
    # h-brk3: 1000 km away Navion answered B ~ 1e-23 T, and currents_for (no limits) ~7.7e21 A.
    # The workspace is the file's Workspace_Dimensions (read here by PyYAML), accepted up to
    # half its extent beyond each face; fields, gradients, unit fields and current solves
    doc = yaml.safe_load(_data_file(NAVION_FILE).read_text())
    box = np.array(doc["Workspace_Dimensions"], dtype=float)
    model = _model("navion").with_limits(np.inf)
    assert model.workspace.tolist() == box.tolist()
    lo, hi = box.T
    edge = np.array([hi + 0.5 * (hi - lo), lo - 0.5 * (hi - lo)])  # corners of what is accepted
    driven = model.with_currents([1.0, -2.0, 0.5])
    anywhere = driven.replace(workspace=None)
    np.testing.assert_array_equal(driven.B_and_gradient(edge)[1], anywhere.gradient(edge))
    beyond = np.array([[0.0, 0.0, 0.0], edge[1] * (1 + 1e-9)])
    with pytest.raises(
        ValueError, match=r"points\[1\] = \(-235, -202, -243.2\) mm is outside"
    ) as err:
        driven.B(beyond)
    assert "in mm?" not in str(err.value)
    far = (1e6, 0.0, 0.0)
    ws = r"\(1e\+09, 0, 0\) mm is outside the calibrated workspace \(model Navion.*: x in \[-123,"
    for call in (driven.B, driven.gradient, driven.hessian, model.unit_fields, model.fixed_field):
        with pytest.raises(ValueError, match=r"points\[0\] = " + ws):
            call(far)
    with pytest.raises(ValueError, match=r"at = " + ws):
        model.currents_for(B=(0.0, 0.0, 0.02), at=far)
    with pytest.raises(ValueError, match=r"points\[0\] = \(3e\+04, 0, 0\) mm.*points in mm"):
        driven.B([30.0, 0.0, 0.0])  # 30 mm meant
    assert np.isfinite(anywhere.B(far)).all()  # without a workspace: the dipole sum anywhere
    # uniformity's default search radius (to the nearest source) stops at the workspace's
    # nearest face, here x = -123 mm from the centre (the sources are >= 258 mm away: rays
    # sampled out to them raised)
    rep = coils.uniformity(driven, 1e-6, directions=4, samples=4)
    assert rep.sphere <= -box[0, 0]


def test_malformed_workspace_is_named(tmp_path):
    path = tmp_path / "bad_model.yaml"
    path.write_text(GOOD + "Workspace_Dimensions: [[-0.1, 0.1], [0.1, -0.1], [-0.1, 0.1]]\n")
    with pytest.raises(ValueError, match=r"bad_model.yaml: Workspace_Dimensions must be .*min bel"):
        MPEM.from_yaml(path)
    path.write_text(GOOD + "Workspace_Dimensions: [[-0.1, 0.1], [-0.1, 0.1]]\n")
    with pytest.raises(ValueError, match=r"bad_model.yaml: Workspace_Dimensions must be 3 pairs"):
        MPEM.from_yaml(path)
