"""Events of the path engine reach the user: :func:`coilrod.path.warn_events`.

Properties checked:
* one :class:`StabilityWarning` per event of a real run (two snap-throughs of the fold
  ``u^3 - u + s`` and a loss and regain of stability of a pitchfork), in order, each naming
  its critical scale (``.6g``), its requested scales and, for a snap, the landing scale;
* no event, no warning; an event without ``between`` is described by its own scale;
* the warning points at the caller (``stacklevel``).
"""

import warnings

import numpy as np
import pytest
from _toy_problems import FOLD_SCALE, fold, pitchfork

from coilrod.path import StabilityWarning, follow_load, warn_events


def events_of_runs():
    snaps = follow_load(fold(), np.ones(1), [0.5, 1.0, 0.0, -0.5]).events
    forks = follow_load(pitchfork(0.7371), np.zeros(1), [2.0, 0.0]).events
    return snaps + forks


def test_one_warning_per_event_naming_its_scales():
    events = events_of_runs()
    assert [e["kind"] for e in events] == ["snap", "snap", "bifurcation", "bifurcation"]
    with pytest.warns(StabilityWarning) as record:
        warn_events(events, "the toy path")
    messages = [str(w.message) for w in record if issubclass(w.category, StabilityWarning)]
    assert len(messages) == len(events)
    for msg, e in zip(messages, events, strict=True):
        a, b = e["between"]
        assert msg.startswith("snap-through: the toy path" if e["kind"] == "snap" else "the toy")
        assert f"{e['scale']:.6g}" in msg
        assert f"between scales {a:g} and {b:g}" in msg
        if e["kind"] == "snap":
            assert f"continued from scale {e['landing']:.6g}" in msg
            assert abs(abs(e["scale"]) - FOLD_SCALE) < 1e-4
        else:
            assert ("lost" if not e["stable"] else "regained") in msg
            assert f"{0.7371:.6g}" in msg


def test_no_event_no_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_events([])


def test_event_without_between_uses_its_scale():
    with pytest.warns(StabilityWarning, match=r"between scales 1.25 and 1.25"):
        warn_events([{"kind": "bifurcation", "scale": 1.25, "stable": False}])


def test_warning_points_at_the_caller():
    with pytest.warns(StabilityWarning) as record:
        warn_events([{"kind": "bifurcation", "scale": 1.0, "stable": True}], stacklevel=2)
    assert record[0].filename == __file__
