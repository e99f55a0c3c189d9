"""The seed paper's magnetization cases and robot (L = 40 mm, D = L/20, M0 = 640 kA/m).

|M| = M0 * phi(s) with phi the particle volume fraction.  The seed does not give phi for M(1),
M(2) and M(4.x); the defaults below use phi = 0.2 (|M| = 128 kA/m, the value of Wang et al.'s
hard-magnetic elastica experiments) and are arguments, not hidden constants.
"""

from __future__ import annotations

import math

import numpy as np

from coils._validate import positive

from .magnetization import Magnetization
from .rod import Rod
from .sections import Circle

__all__ = [
    "SEED_LENGTH",
    "SEED_M0",
    "seed_rod",
    "M1",
    "M2",
    "M3",
    "M41",
    "M42",
    "EXAMPLE_M41_LAYOUT",
]

#: Robot length of the seed, m.
SEED_LENGTH = 0.04
#: Saturation magnetization scale M0 of the seed, A/m.
SEED_M0 = 640e3


def M1(length: float = SEED_LENGTH, M0: float = SEED_M0, phi: float = 0.2) -> Magnetization:
    """M(1): uniform axial magnetization |M| = M0 phi (A/m), theta_m = 0.

    ``length`` (m) is accepted like the other presets' (M(1) does not depend on it; it is
    checked to be a positive length)."""
    positive(length, "length")
    return Magnetization(M0 * phi, 0.0, label=f"M(1) |M|={M0 * phi:g} A/m")


def M2(
    length: float = SEED_LENGTH, variant: str = "a", M0: float = SEED_M0, phi: float = 0.2
) -> Magnetization:
    """M(2): direction varies along the rod.

    ``variant="a"``: theta_m = pi s / (2L) (seed Fig. 4a);
    ``variant="b"``: theta_m = 3 pi s / (2L) - pi/2 (seed Fig. 4b).
    """
    if variant == "a":
        angle = lambda s: math.pi * np.asarray(s) / (2 * length)  # noqa: E731
    elif variant == "b":
        angle = lambda s: 3 * math.pi * np.asarray(s) / (2 * length) - math.pi / 2  # noqa: E731
    else:
        raise ValueError(f"variant must be 'a' or 'b'; got {variant!r}")
    return Magnetization(M0 * phi, angle, label=f"M(2{variant})")


def M3(length: float = SEED_LENGTH, M0: float = SEED_M0, slope: float = 0.4) -> Magnetization:
    """M(3): magnitude varies, phi = slope * s / L (seed: 0.4 s/L), axial direction."""
    return Magnetization(
        lambda s: M0 * slope * np.asarray(s) / length, 0.0, label=f"M(3) phi={slope:g} s/L"
    )


#: Example segment layout for M(4.1): NOT the optimised design of the seed's ref. [7], whose
#: values are not available here.  Fractions of L from the clamp and particle fractions phi:
#: weaker near the clamp, stronger toward the tip.  Enter any layout with Magnetization.segments.
EXAMPLE_M41_LAYOUT = {
    "fractions": (0.25, 0.25, 0.25, 0.25),
    "phi": (0.05, 0.10, 0.15, 0.20),
}


def M41(
    length: float = SEED_LENGTH, M0: float = SEED_M0, layout: dict | None = None
) -> Magnetization:
    """M(4.1): segments of different magnitude, all axial (example layout by default)."""
    layout = EXAMPLE_M41_LAYOUT if layout is None else layout
    lengths = [f * length for f in layout["fractions"]]
    return Magnetization.segments(
        lengths, [M0 * p for p in layout["phi"]], 0.0, label="M(4.1) example layout"
    )


def M42(
    length: float = SEED_LENGTH,
    M0: float = SEED_M0,
    layout: dict | None = None,
    segment: int = -1,
    angle: float = -math.pi / 4,
) -> Magnetization:
    """M(4.2): M(4.1) with one segment's direction changed.

    By default the tip segment is turned to theta_m = -pi/4: once the rod has bent, it meets the
    field closer to perpendicular, so M(4.2) deflects more than M(4.1) at high field (the trend
    of the seed's Fig. 5; the seed's exact layout is not available).
    """
    layout = EXAMPLE_M41_LAYOUT if layout is None else layout
    lengths = [f * length for f in layout["fractions"]]
    angles = np.zeros(len(lengths))
    angles[segment] = angle
    return Magnetization.segments(
        lengths,
        [M0 * p for p in layout["phi"]],
        angles,
        label=f"M(4.2) segment {segment} at {angle:.3g} rad",
    )


def seed_rod(
    magnetization: Magnetization | None = None,
    youngs_modulus: float = 1e6,
    length: float = SEED_LENGTH,
    diameter: float | None = None,
) -> Rod:
    """The seed's robot: L = 40 mm, circular, E = 1 MPa by default (M(1) if None).

    Parameters
    ----------
    magnetization : Magnetization, optional
    youngs_modulus : float
        E, Pa.
    length : float
        L, m.  The section keeps the seed's slenderness: **the diameter is L / 20** (2 mm at
        40 mm; 3 mm for ``length=0.06``) -- give ``diameter`` to fix it instead.
    diameter : float, optional
        D, m (default L / 20).
    """
    return Rod(
        length=length,
        youngs_modulus=youngs_modulus,
        section=Circle(diameter=length / 20 if diameter is None else diameter),
        magnetization=magnetization if magnetization is not None else M1(),
    )
