"""Scenes: TOML files with units, the planner, the runner, figures and the ``coilrod`` CLI."""

from .parse import MODELS, PRESETS, Scene, SceneError, load_scene, parse_scene

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "MODELS", "PRESETS"]
