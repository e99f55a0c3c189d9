"""Events along an equilibrium path: loss or gain of stability (bifurcation) and snap-through.

The engine records each event as a dict (so results stay plain data):

* ``kind = "bifurcation"``: the path crossed a point where the stability changes while the
  equilibrium continues (a branch point; the solver stays on its branch).  ``scale`` is the
  critical scale, located by cutting the load step to ``bifurcation_tol`` of the requested step
  (and interpolated with the model's stability measure); ``stable`` the new stability;
  ``between`` the two requested scales around it; the planar rod adds ``mode``
  ("in-plane" or "out-of-plane").
* ``kind = "snap"``: the branch ended at a limit point (fold); the path was followed around it
  by pseudo-arclength continuation until it was stable again beyond the fold.  ``scale`` is
  the fold scale (the extreme scale reached on the old branch), ``landing`` the scale at which
  loading continued on the new branch, ``stable`` True.

``index`` is the index of the first requested scale after the event.
"""

from __future__ import annotations

import warnings

__all__ = ["StabilityWarning", "warn_events"]


class StabilityWarning(UserWarning):
    """An equilibrium branch followed by the solver lost (or regained) stability."""


def warn_events(events: list[dict], what: str = "the equilibrium branch", stacklevel: int = 3):
    """Issue one :class:`StabilityWarning` per event (see the module docstring)."""
    for e in events:
        a, b = e.get("between", (e["scale"], e["scale"]))
        if e["kind"] == "snap":
            msg = (
                f"snap-through: {what} ends at a limit point at scale {e['scale']:.6g} "
                f"(between scales {a:g} and {b:g}); the rod jumps to another stable branch "
                f"(continued from scale {e['landing']:.6g})"
            )
        else:
            change = "regained" if e["stable"] else "lost"
            msg = (
                f"{what} {change} stability between scales {a:g} and {b:g} (estimated "
                f"critical scale {e['scale']:.6g}): a bifurcation or limit point; the solver "
                "stays on its branch"
            )
            if e.get("mode") == "out-of-plane":
                msg += (
                    " (an out-of-plane mode: the rod would buckle out of its plane; the planar "
                    "solver stays on the planar branch -- model='spatial' with an imperfection "
                    "follows the rod out of the plane)"
                )
        warnings.warn(msg, StabilityWarning, stacklevel=stacklevel)
