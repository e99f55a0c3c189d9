"""The one path-following engine every model drives (Newton, load stepping, arclength, events)."""

from .events import StabilityWarning

__all__ = ["StabilityWarning"]
