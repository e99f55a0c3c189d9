"""What a newcomer meets in the first hour (issue "The first hour"): presets and units that
cannot surprise, namespaces that show the API, packaging that runs the notebooks."""

from __future__ import annotations

import math
import tomllib
import types
import warnings
from pathlib import Path

import pytest

import coilrod
import coils
from coilrod import Circle, Magnetization, Rectangle, Rod, UnitsWarning, presets

ROOT = Path(__file__).resolve().parents[1]


class TestPresets:
    def test_every_magnetization_preset_takes_a_length(self):
        for make in (presets.M1, presets.M2, presets.M3, presets.M41, presets.M42):
            m = make(length=0.06)
            assert isinstance(m, Magnetization)
        # M(1) is uniform: its length changes nothing, but a bad one is refused by name
        assert presets.M1(length=0.06).magnitude(0.05) == pytest.approx(640e3 * 0.2)
        with pytest.raises(ValueError, match="length"):
            presets.M1(length=-1.0)

    def test_seed_rod_says_its_diameter_follows_the_length(self):
        rod = presets.seed_rod(length=0.06)
        assert rod.section.diameter == pytest.approx(0.06 / 20)
        assert "diameter=0.003" in repr(rod)
        assert "D = L / 20" in presets.seed_rod.__doc__ or "L / 20" in presets.seed_rod.__doc__
        fixed = presets.seed_rod(length=0.06, diameter=2e-3)
        assert fixed.section.diameter == 2e-3
        # E I = E pi D^4 / 64 by hand
        assert fixed.bending_stiffness == pytest.approx(1e6 * math.pi * 2e-3**4 / 64, rel=1e-15)


class TestUnits:
    @pytest.mark.parametrize(
        ("args", "match"),
        [
            ((40, 1e6, Circle(2e-3)), r"length = 40 m.*metres"),
            ((0.04, 1e6, Circle(0.02)), r"diameter = 0\.02 m is over L/3.*metres"),
            ((0.04, 1e6, Rectangle(2e-3, 0.03)), r"section side = 0\.03 m"),
            ((0.04, 1.0, Circle(2e-3)), r"youngs_modulus = 1 Pa.*Pa"),
            ((0.04, 2e11, Circle(2e-3)), r"youngs_modulus = 2e\+11 Pa"),
        ],
    )
    def test_a_robot_that_cannot_be_warns_naming_value_and_unit(self, args, match):
        with pytest.warns(UnitsWarning, match=match):
            Rod(*args, Magnetization(128e3, 0.0))

    def test_magnetization_beyond_any_magnet_warns(self):
        with pytest.warns(UnitsWarning, match=r"3e\+06 A/m is over 2 MA/m"):
            Rod(0.04, 1e6, Circle(2e-3), Magnetization(3e6, 0.0))

    def test_the_seed_robot_is_silent(self):
        with warnings.catch_warnings():
            warnings.simplefilter("error", UnitsWarning)
            presets.seed_rod(presets.M42())
            Rod(0.9, 5e3, Circle(0.3), Magnetization(1.9e6, 0.0))  # just inside every bound


class TestNamespaces:
    @pytest.mark.parametrize("package", [coils, coilrod])
    def test_dir_shows_the_api_only(self, package):
        assert dir(package) == sorted(package.__all__)
        for name in package.__all__:
            assert hasattr(package, name)

    def test_no_module_in_the_api_but_presets(self):
        for package in (coils, coilrod):
            modules = [
                n for n in package.__all__ if isinstance(getattr(package, n), types.ModuleType)
            ]
            assert modules == ["presets"]
        assert "elastica" not in coilrod.__all__
        assert callable(coilrod.elastica.elastica)  # still importable for those who use it


class TestPackaging:
    def test_notebooks_extra_executes_notebooks(self):
        meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
        extra = " ".join(meta["project"]["optional-dependencies"]["notebooks"])
        for pkg in ("jupyterlab", "nbconvert", "ipykernel"):
            assert pkg in extra

    def test_demo_output_is_ignored_by_git(self):
        assert "coilrod-demo/" in (ROOT / ".gitignore").read_text().split()
