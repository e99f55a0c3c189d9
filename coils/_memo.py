"""The package's one bounded-cache rule: a dict kept as a short most-recent-last memory.

Used by the rod's caches (:func:`coilrod.rod.mesh._remember`) and by an obstacle's
remembered searches (:meth:`coilrod.contact.Vessel._located`); it imports nothing, so an
obstacle can use it without importing the rod package.
"""

from __future__ import annotations

__all__ = ["remember"]


def remember(cache: dict, key, value, size: int):
    """Store ``value`` under ``key`` in ``cache`` as its most recent entry (a key stored again
    moves there), dropping the oldest entry beyond ``size`` entries; returns ``value``."""
    if cache.pop(key, None) is None and len(cache) >= size:
        cache.pop(next(iter(cache)), None)
    cache[key] = value
    return value
