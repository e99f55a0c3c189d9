"""Scenes: TOML files with units, the planner, the runner, figures and the ``coilrod`` CLI."""

from __future__ import annotations

import importlib

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "MODELS", "PRESETS"]


def __getattr__(name: str):
    """Import :mod:`.parse` on first use of a public name (``coilrod --help`` needs none)."""
    if name not in __all__:
        raise AttributeError(f"module 'coilrod.scene' has no attribute {name!r}")
    value = getattr(importlib.import_module(".parse", __name__), name)
    globals()[name] = value
    return value
