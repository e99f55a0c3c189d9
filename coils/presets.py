"""Coil systems of real arrangements, built from air coils (Biot-Savart; no iron cores).

Each preset returns a :class:`~coils.CoilSystem` with every channel at zero current, current
limits and copper resistances, centred on the workspace centre ``center``; drive it with
:meth:`~coils.CoilSystem.with_currents` or :meth:`~coils.CoilSystem.currents_for`.  Coils are
thin (one filament of N I ampere-turns per coil) unless a ``winding=(width, height)`` section is
given; resistances are those of round copper wire of ``wire_diameter`` at 20 degC
(:mod:`coils.copper`).  Sizes are defaults to start from, not data of a particular machine.

Three orthogonal Helmholtz pairs (:func:`three_axis_helmholtz`)
    Pairs along x, y and z, nested with radii 100, 140, 180 mm, each at its own spacing R (the
    rings interlock; the closest wires of two pairs are ``sqrt(5)/2`` times the difference of
    their radii apart, 45 mm, room for the 28 mm square windings of 200 turns of 2 mm wire);
    200 turns, 10 A: uniform fields of any direction, 18.0, 12.8 and 10.0 mT at the limit, 580 W
    with all three at it.  Centre field per pair ``(4/5)^{3/2} mu0 N I / R``, uniform to 1 %
    within ``0.31 R`` along its axis.  The usual laboratory rig for rotating uniform fields.

Three Helmholtz pairs and a Maxwell pair (:func:`helmholtz_maxwell`)
    The three pairs above and a Maxwell gradient pair (radius 240 mm, spacing ``sqrt(3) R``,
    500 turns, 15 A; default axis y, the seed's Config (B)) outside them: any uniform field
    plus the gradient ``g diag(-1/2, 1, -1/2)`` along the Maxwell axis, ``g = 48 sqrt(3) /
    7^{5/2} mu0 N I / R^2`` (0.105 T/m and 1.9 kW at the limit).  Of the kind of Yesin,
    Vollmers & Nelson, Int. J. Robot. Res. 25 (2006) 527, who orient a microrobot with the
    uniform field of a Helmholtz pair and pull it with the gradient of a Maxwell pair.

Eight coils on a hemisphere (:func:`eight_coil_hemisphere`)
    Eight identical coils (radius 60 mm, 600 turns, 20 A: 3.0 mT each at the centre, 0.5 kW)
    with centres on a hemisphere of radius 200 mm below the workspace (``z <= 0``), every axis
    pointing at the workspace centre: four in the equatorial plane at azimuths 0, 90, 180,
    270 deg and four at 45 deg from the downward pole at azimuths 45, 135, 225, 315 deg; the
    half-space above stays open for access.  With eight channels the field (3 components) and
    the gradient (5) at the centre are independently controllable; eight is the least number
    of electromagnets that does this without singularities (Petruska & Nelson, IEEE Trans.
    Robot. 31 (2015) 714).  The arrangement is of the kind of the eight-electromagnet systems
    OctoMag (Kummer et al., IEEE Trans. Robot. 26 (2010) 1006) and its clinical scale-up
    CardioMag (Aeon Scientific), modelled and calibrated in Petruska, Edelmann & Nelson,
    "Model-based calibration for magnetic manipulation", IEEE Trans. Magn. 53(7) (2017), and
    compared in Pourkand & Abbott, "A critical analysis of eight-electromagnet manipulation
    systems", IEEE Robot. Autom. Lett. 3(4) (2018); clinical eMNS such as Navion (Gervasoni et
    al., Adv. Mater. 2024) follow the same principle with fewer coils.  It is not the geometry
    of any of them, and those use iron cores, which make several times the field of these air
    coils.

Calibrated eMNS models (:func:`cardiomag`, :func:`navion`, :func:`octomag`)
    Not air coils: :class:`~coils.MPEM` point-dipole models fitted to measurements of systems
    with iron cores, shipped as package data (``coils/data``) from ETH Zurich's
    github.com/ethz-msrl/Workspace_eMNS (``models/``, Apache-2.0; ``coils/data/README.md``
    and ``LICENSE``), the models of Boehler et al., "On the workspace of electromagnetic
    navigation systems", IEEE Trans. Robot. (2022), doi:10.1109/TRO.2022.3197107.
    Frames and centres are the calibrations' (origin at the workspace centre).
"""

from __future__ import annotations

import math

import numpy as np

from ._validate import as_array, as_axis, as_vector, positive
from .mpem import MPEM
from .pairs import Coil, HelmholtzPair, MaxwellPair
from .system import CoilSystem

__all__ = [
    "three_axis_helmholtz",
    "helmholtz_maxwell",
    "eight_coil_hemisphere",
    "cardiomag",
    "navion",
    "octomag",
]

_AXES = ("x", "y", "z")


def _per_axis(value, name: str) -> tuple[float, float, float]:
    """A positive scalar or three positive values (x, y, z)."""
    arr = as_array(value, name)
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a scalar or have shape (3,); got {arr.shape}")
    return tuple(positive(v, f"{name}[{k}]") for k, v in enumerate(arr))


def _helmholtz_pairs(radii, turns, wire_diameter, winding, center):
    radii = _per_axis(radii, "radii")
    turns = _per_axis(turns, "turns")
    return [
        HelmholtzPair(
            radii[k], turns[k], 0.0, axis=a, center=center, winding=winding,
            wire_diameter=wire_diameter,
        )
        for k, a in enumerate(_AXES)
    ]  # fmt: skip


def three_axis_helmholtz(
    radii=(0.100, 0.140, 0.180),
    turns=200,
    max_current=10.0,
    *,
    wire_diameter: float = 2.0e-3,
    winding=None,
    center=(0.0, 0.0, 0.0),
) -> CoilSystem:
    """Three orthogonal, nested Helmholtz pairs: uniform fields of any direction.

    Parameters
    ----------
    radii : float or array-like, shape (3,)
        Coil radius of the x, y and z pairs, m (each pair at spacing R).  Different radii let
        the pairs nest; equal radii would make the wires touch.
    turns : float or array-like, shape (3,)
        Turns per coil of each pair.
    max_current : float or array-like, shape (3,)
        Current limit per pair, A.
    wire_diameter : float
        Bare copper wire diameter, m (sets the resistances).
    winding : (width, height), optional
        Winding cross-section of every coil, m; default thin coils.
    center : array-like, shape (3,)
        Common centre, m.

    Returns
    -------
    CoilSystem
        Channels ``("x Helmholtz", "y Helmholtz", "z Helmholtz")`` at 0 A.

    Examples
    --------
    >>> from coils import presets
    >>> system = presets.three_axis_helmholtz()
    >>> system.names, system.max_current
    (('x Helmholtz', 'y Helmholtz', 'z Helmholtz'), array([10., 10., 10.]))
    >>> B = system.with_currents([10.0, 0.0, 0.0]).B(system.center)[0]
    >>> round(1e3 * float(B[0]), 3)    # mT, (4/5)^1.5 mu0 N I / R
    17.984
    """
    pairs = _helmholtz_pairs(radii, turns, wire_diameter, winding, center)
    return CoilSystem(
        pairs,
        center=center,
        max_current=_per_axis(max_current, "max_current"),
        names=tuple(f"{a} Helmholtz" for a in _AXES),
    )


def helmholtz_maxwell(
    radii=(0.100, 0.140, 0.180),
    turns=200,
    max_current=10.0,
    *,
    maxwell_radius: float = 0.240,
    maxwell_turns: float = 500,
    maxwell_max_current: float = 15.0,
    maxwell_axis="y",
    wire_diameter: float = 2.0e-3,
    winding=None,
    center=(0.0, 0.0, 0.0),
) -> CoilSystem:
    """Three orthogonal Helmholtz pairs and a Maxwell gradient pair around them.

    Parameters
    ----------
    radii, turns, max_current
        Of the three Helmholtz pairs, as for :func:`three_axis_helmholtz` (m, -, A).
    maxwell_radius : float
        Radius of the Maxwell coils, m (spacing ``sqrt(3) R``); it must exceed the Helmholtz
        radii so that the Maxwell coils sit outside the Helmholtz pairs.
    maxwell_turns : float
        Turns per Maxwell coil.
    maxwell_max_current : float
        Current limit of the Maxwell pair, A.
    maxwell_axis : {"x", "y", "z"} or array-like, shape (3,)
        Axis of the gradient pair (default y: the seed's Config (B)).
    wire_diameter, winding, center
        As for :func:`three_axis_helmholtz`.

    Returns
    -------
    CoilSystem
        Channels ``("x Helmholtz", "y Helmholtz", "z Helmholtz", "Maxwell")`` at 0 A.

    Examples
    --------
    >>> from coils import presets
    >>> system = presets.helmholtz_maxwell()
    >>> G = system.with_currents([0.0, 0.0, 0.0, 15.0]).gradient(system.center)[0]
    >>> round(float(G[1, 1]), 4)       # T/m, 48 sqrt(3)/7^2.5 mu0 N I / R^2
    0.1049
    """
    pairs = _helmholtz_pairs(radii, turns, wire_diameter, winding, center)
    maxwell_radius = positive(maxwell_radius, "maxwell_radius")
    largest = max(p.radius for p in pairs)
    if maxwell_radius <= largest:
        raise ValueError(
            f"maxwell_radius must exceed the largest Helmholtz radius {largest} m (the Maxwell "
            f"coils sit outside the pairs); got {maxwell_radius}"
        )
    maxwell = MaxwellPair(
        maxwell_radius,
        positive(maxwell_turns, "maxwell_turns"),
        0.0,
        axis=as_axis(maxwell_axis, "maxwell_axis"),
        center=center,
        winding=winding,
        wire_diameter=wire_diameter,
    )
    limits = (*_per_axis(max_current, "max_current"),
              positive(maxwell_max_current, "maxwell_max_current"))  # fmt: skip
    return CoilSystem(
        [*pairs, maxwell],
        center=center,
        max_current=limits,
        names=(*(f"{a} Helmholtz" for a in _AXES), "Maxwell"),
    )


#: Polar angles (from the downward pole -z, deg) and azimuths (deg) of the hemisphere's coils.
HEMISPHERE_LAYOUT = tuple(
    [(90.0, 90.0 * k) for k in range(4)] + [(45.0, 45.0 + 90.0 * k) for k in range(4)]
)


def eight_coil_hemisphere(
    distance: float = 0.200,
    radius: float = 0.060,
    turns: float = 600,
    max_current: float = 20.0,
    *,
    wire_diameter: float = 2.0e-3,
    winding=None,
    center=(0.0, 0.0, 0.0),
) -> CoilSystem:
    """Eight coils on a hemisphere below the workspace, all pointing at its centre.

    Coil ``k`` sits at ``center - distance * (sin t cos p, sin t sin p, cos t)`` with
    ``(t, p)`` the polar angle from the downward pole and the azimuth of
    :data:`HEMISPHERE_LAYOUT`: four coils in the equatorial plane (t = 90 deg, p = 0, 90, 180,
    270 deg) and four at t = 45 deg (p = 45, 135, 225, 315 deg).  Its axis is the unit vector
    from the coil to ``center``, so a positive current makes a field at the centre pointing
    away from the coil.  See :mod:`coils.presets` for the systems of this kind.

    Parameters
    ----------
    distance : float
        From the workspace centre to each coil's centre, m.
    radius : float
        Coil radius, m (below ``distance``).
    turns : float
        Turns per coil.
    max_current : float
        Current limit of every coil, A.
    wire_diameter : float
        Bare copper wire diameter, m (sets the resistances).
    winding : (width, height), optional
        Winding cross-section of every coil, m; default thin coils.
    center : array-like, shape (3,)
        Workspace centre, m.

    Returns
    -------
    CoilSystem
        Eight channels named by their angles, at 0 A.

    Examples
    --------
    >>> import numpy as np
    >>> from coils import presets
    >>> system = presets.eight_coil_hemisphere()
    >>> Bu, Gu = system.unit_fields(system.center)
    >>> A = np.vstack([Bu[0], Gu[0].reshape(9, 8)])
    >>> int(np.linalg.matrix_rank(A, tol=1e-9 * np.abs(A).max()))   # 3 field + 5 gradient
    8
    """
    distance = positive(distance, "distance")
    radius = positive(radius, "radius")
    if radius >= distance:
        raise ValueError(
            f"radius must be below distance {distance} m (the coils face the centre from "
            f"outside it); got {radius}"
        )
    c = as_vector(center, "center")
    coils, names = [], []
    for t_deg, p_deg in HEMISPHERE_LAYOUT:
        t, p = math.radians(t_deg), math.radians(p_deg)
        toward = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
        coils.append(
            Coil(
                radius, turns, 0.0, axis=toward, center=c - distance * toward,
                winding=winding, wire_diameter=wire_diameter,
            )
        )  # fmt: skip
        names.append(f"coil polar {t_deg:g} deg azimuth {p_deg:g} deg")
    return CoilSystem(coils, center=c, max_current=max_current, names=names)


# -- calibrated eMNS models (MPEM) ----------------------------------------------------------------
#: The shipped calibration files (coils/data, from github.com/ethz-msrl/Workspace_eMNS).
CARDIOMAG_FILE = "C_Mag_Calibration_06-25-2015_no_offset.yaml"
NAVION_FILE = "Navion_2_Calibration_24-02-2020.yaml"
OCTOMAG_FILE = "mns_8coils_octomag.yaml"


def _data_file(name: str):
    from importlib.resources import files

    return files("coils").joinpath("data", name)


def cardiomag(max_current: float = 20.0) -> MPEM:
    """CardioMag (Aeon Scientific): the eight-electromagnet clinical eMNS, calibrated MPEM.

    The calibration of June 2015 (8 coils, 6 to 8 dipole sources each, and 8 offset sources of
    the current-independent field), file ``C_Mag_Calibration_06-25-2015_no_offset.yaml`` of
    github.com/ethz-msrl/Workspace_eMNS (Apache-2.0).

    Parameters
    ----------
    max_current : float
        Limit of every coil, A.  Default 20 A: the limit the calibration's authors use for
        CardioMag in the workspace analysis of Boehler et al., IEEE Trans. Robot. 2022
        (``Imax = 20`` in the repository's ``04_cardiomag_application.ipynb``); check it
        against your installation's amplifiers.

    Returns
    -------
    MPEM
        Eight channels ``Coil_0`` ... ``Coil_7`` at 0 A.

    Examples
    --------
    >>> from coils import presets
    >>> cmag = presets.cardiomag()
    >>> len(cmag.channels), float(cmag.max_current[0])
    (8, 20.0)
    """
    return MPEM.from_yaml(_data_file(CARDIOMAG_FILE), max_current=max_current)


def navion(max_current: float = 35.0) -> MPEM:
    """Navion: the three-coil clinical eMNS of Gervasoni et al. (Adv. Mater. 36 (2024)
    2310701, doi:10.1002/adma.202310701), calibrated MPEM (3 dipoles per coil).

    Parameters
    ----------
    max_current : float
        Limit of every coil, A.  Default 35 A: the limit of the authors' field maps of Navion
        (``05_navion_application.ipynb`` of github.com/ethz-msrl/Workspace_eMNS, "maximum
        field magnitude for 35 A", and ``MAX_CURRENT = 35`` in mag_manip's tests of this
        calibration).

    Returns
    -------
    MPEM
        Three channels ``Coil_0`` ... ``Coil_2`` at 0 A.

    Examples
    --------
    >>> import numpy as np
    >>> from coils import presets
    >>> nav = presets.navion()
    >>> Bu, Gu = nav.unit_fields([0.0, 0.0, 0.0])
    >>> np.round(1e3 * Bu[0, :, 0], 4)      # mT per ampere of Coil_0 at the centre
    array([ 0.0005, -0.2905, -0.4138])
    """
    return MPEM.from_yaml(_data_file(NAVION_FILE), max_current=max_current)


def octomag(*, max_current) -> MPEM:
    """An idealised OctoMag-like eight-coil eMNS (one dipole per coil), as an MPEM.

    The model ``mns_8coils_octomag.yaml`` of github.com/ethz-msrl/Workspace_eMNS (Boehler et
    al., IEEE Trans. Robot. 2022): eight dipoles of 1e-4 T m^3/A, four in the plane z = 0 at
    150 mm pointing at the centre and four below it, in the arrangement of OctoMag (Kummer et
    al., IEEE Trans. Robot. 26 (2010) 1006).  It is not a calibration of a built system, so
    it has no published current limit: give one.

    Parameters
    ----------
    max_current : float or array-like, shape (8,)
        Limit of every coil, A (required).

    Returns
    -------
    MPEM
        Eight channels at 0 A.
    """
    return MPEM.from_yaml(_data_file(OCTOMAG_FILE), max_current=max_current)
