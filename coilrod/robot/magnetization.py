"""Magnetization profiles along the rod: magnitude |M|(s) in A/m, angle theta_m(s) and
elevation psi_m(s) in rad.

The angle is measured from the local tangent, in the bending plane (counter-clockwise about z);
the elevation lifts the vector out of that plane, toward the binormal.  In the body frame
(tangent, normal, binormal) -- (x, y, z) in the reference (straight, along +x) configuration --
the magnetization vector is ``|M| (cos theta_m cos psi_m, sin theta_m cos psi_m, sin psi_m)``;
a planar magnetization (psi_m = 0) is ``|M| (cos theta_m, sin theta_m, 0)``.  In the deformed
configuration it is rotated with the cross-section, ``m = R M``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from coils._validate import as_array, as_count, finite_scalar, positive

__all__ = ["Magnetization"]

Profile = float | Callable[[np.ndarray], np.ndarray]


def _check_profile(value, name: str):
    if callable(value):
        return value
    return finite_scalar(value, name)


class Magnetization:
    """Remanent magnetization of the robot body.

    Parameters
    ----------
    magnitude : float or callable
        |M| in A/m, a constant or a function of arc length ``s`` (m, ndarray) returning an
        ndarray of the same shape.  The seed writes |M| = M0 * phi(s), phi the particle fraction.
    angle : float or callable
        theta_m in rad from the local tangent, in the bending plane; constant or function of
        ``s`` (m).
    elevation : float or callable, optional
        psi_m in rad out of the bending plane (toward the binormal +z of the reference rod);
        constant or function of ``s`` (m).  Default 0: a planar magnetization.
    breakpoints : sequence of float, optional, keyword-only
        Arc lengths (m) where the profile jumps; solvers place nodes and element boundaries there.
    label : str, optional, keyword-only
        A name for reports and ``repr``.

    Raises
    ------
    ValueError
        A constant magnitude, angle or elevation that is not a finite real number (naming it);
        a callable one that returns NaN or inf is reported when it is evaluated.

    Examples
    --------
    >>> import numpy as np
    >>> m = Magnetization(magnitude=128e3, angle=0.0)
    >>> m.vector(np.array([0.0, 0.01]))
    array([[128000.,      0.],
           [128000.,      0.]])
    >>> up = Magnetization(128e3, 0.0, elevation=np.pi / 2)   # along the binormal
    >>> np.round(up.vector3(np.array([0.0])), 6) + 0.0
    array([[     0.,      0., 128000.]])
    >>> up.is_planar
    False
    """

    def __init__(
        self,
        magnitude: Profile = 0.0,
        angle: Profile = 0.0,
        elevation: Profile = 0.0,
        *,
        breakpoints: Sequence[float] = (),
        label: str = "",
    ):
        self._magnitude = _check_profile(magnitude, "magnitude")
        self._angle = _check_profile(angle, "angle")
        self._elevation = _check_profile(elevation, "elevation")
        self.breakpoints = tuple(sorted(as_array(breakpoints, "breakpoints", ("n",)).tolist()))
        self.label = label

    def check_length(self, length: float) -> None:
        """Raise ValueError unless the profile fits a rod of ``length`` (m).

        Breakpoints must lie on the rod, in [0, length]; segments (:meth:`segments`) must add
        up to the length (to rounding, 1e-9 relative): otherwise the last segment would
        silently stretch or shrink to the tip.
        """
        slack = 1e-9 * length
        bad = [b for b in self.breakpoints if not -slack <= b <= length + slack]
        if bad:
            raise ValueError(
                f"magnetization breakpoints must lie on the rod (0 to {length:g} m); got "
                f"{bad[0]:g} m"
            )
        edges = getattr(self, "segment_edges", None)
        if edges is not None and abs(edges[-1] - length) > slack:
            raise ValueError(
                f"magnetization segments add up to {edges[-1]:.12g} m but the rod is "
                f"{length:.12g} m long; the segment lengths must sum to the rod length"
            )

    @property
    def is_constant(self) -> bool:
        """True if magnitude, angle and elevation are all constants."""
        return not (callable(self._magnitude) or callable(self._angle) or callable(self._elevation))

    @property
    def is_planar(self) -> bool:
        """True iff the elevation is the constant 0: M lies in the bending plane everywhere.

        A callable elevation counts as non-planar, whatever it returns (it is not evaluated).
        """
        return not callable(self._elevation) and self._elevation == 0.0

    def check_planar(self, model: str) -> None:
        """Raise ValueError unless the profile is planar (:attr:`is_planar`).

        For the models that see only the bending plane (``model`` names one in the message):
        they would silently drop the out-of-plane part of M.
        """
        if not self.is_planar:
            raise ValueError(
                f"magnetization {self!r} has an out-of-plane elevation; the planar {model} "
                "supports only planar magnetizations (elevation 0)"
            )

    def _eval(self, profile, s: np.ndarray, name: str) -> np.ndarray:
        s = as_array(s, "s")
        if callable(profile):
            out = np.asarray(profile(s), dtype=float)
            out = np.broadcast_to(out, s.shape).astype(float, copy=True)
        else:
            out = np.full(s.shape, profile)
        if not np.all(np.isfinite(out)):
            raise ValueError(f"magnetization {name} is not finite at some arc lengths")
        return out

    def magnitude(self, s) -> np.ndarray:
        """|M|(s) in A/m, same shape as ``s`` (m)."""
        return self._eval(self._magnitude, s, "magnitude")

    def angle(self, s) -> np.ndarray:
        """theta_m(s) in rad from the tangent, same shape as ``s`` (m)."""
        return self._eval(self._angle, s, "angle")

    def elevation(self, s) -> np.ndarray:
        """psi_m(s) in rad out of the bending plane, same shape as ``s`` (m)."""
        return self._eval(self._elevation, s, "elevation")

    def vector(self, s) -> np.ndarray:
        """Body-frame (tangential, normal) components, shape (n, 2), A/m.

        The projection of M on the bending plane, ``|M| cos psi_m (cos theta_m, sin theta_m)``
        (``s``: arc lengths, shape (n,), m); the full vector is :meth:`vector3`.
        """
        s = np.atleast_1d(as_array(s, "s"))
        mag = self.magnitude(s)
        ang = self.angle(s)
        if not self.is_planar:
            mag = mag * np.cos(self.elevation(s))
        return np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)

    def vector3(self, s) -> np.ndarray:
        """Body-frame (tangent, normal, binormal) components, shape (n, 3), A/m.

        ``|M| (cos theta_m cos psi_m, sin theta_m cos psi_m, sin psi_m)`` at the arc lengths
        ``s`` (shape (n,), m); in the reference configuration the frame is (x, y, z).
        """
        s = np.atleast_1d(as_array(s, "s"))
        in_plane = self.vector(s)
        if self.is_planar:
            normal = np.zeros(s.shape)
        else:
            normal = self.magnitude(s) * np.sin(self.elevation(s))
        return np.concatenate([in_plane, normal[..., None]], axis=-1)

    def max_magnitude(self, length: float, samples: int = 2001) -> float:
        """max |M| over s in [0, length] (m, ``samples`` >= 2 points), A/m."""
        length = positive(length, "length")
        samples = as_count(samples, "samples", 2)
        return float(np.max(np.abs(self.magnitude(np.linspace(0.0, length, samples)))))

    # -- constructors -------------------------------------------------------------------------
    @classmethod
    def segments(
        cls,
        lengths: Sequence[float],
        magnitudes: Sequence[float],
        angles: Sequence[float] | float = 0.0,
        elevations: Sequence[float] | float = 0.0,
        label: str = "",
    ) -> Magnetization:
        """Piecewise-constant magnetization from the clamp (s = 0) to the tip.

        Parameters
        ----------
        lengths : sequence of float
            Segment lengths in metres, from the clamp; their sum must equal the length of the
            rod the profile is given to (:class:`~coilrod.Rod` checks it, 1e-9 relative).
        magnitudes : sequence of float
            |M| of each segment, A/m.
        angles : sequence of float or float
            theta_m of each segment, rad from the tangent.
        elevations : sequence of float or float
            psi_m of each segment, rad out of the bending plane (default 0: planar; the
            profile is planar, :attr:`is_planar`, when every elevation is 0).
        label : str
            A name for reports and ``repr``.

        The values are kept as the attributes ``segment_edges`` (m, shape (p + 1,)),
        ``segment_magnitudes``, ``segment_angles`` and ``segment_elevations`` (shape (p,)).

        Examples
        --------
        >>> m = Magnetization.segments([0.02, 0.02], [100e3, 200e3], [0.0, 1.0])
        >>> m.magnitude(np.array([0.01, 0.03])).tolist()
        [100000.0, 200000.0]
        >>> m.is_planar
        True
        """
        lengths = as_array(lengths, "segment lengths", ("n",))
        if len(lengths) == 0:
            raise ValueError("segment lengths must hold at least one segment; got []")
        lengths = np.array([positive(v, "segment length") for v in lengths])
        mags = as_array(magnitudes, "segment magnitudes", ("n",)).copy()
        if np.ndim(angles) == 0:
            angs = np.full(len(lengths), finite_scalar(angles, "segment angle"))
        else:
            angs = as_array(angles, "segment angles", ("n",)).copy()
        if np.ndim(elevations) == 0:
            elevs = np.full(len(lengths), finite_scalar(elevations, "segment elevation"))
        else:
            elevs = as_array(elevations, "segment elevations", ("n",)).copy()
        if not (len(lengths) == len(mags) == len(angs) == len(elevs)):
            raise ValueError(
                "segments need as many magnitudes, angles and elevations as lengths; got "
                f"{len(lengths)} lengths, {len(mags)} magnitudes, {len(angs)} angles, "
                f"{len(elevs)} elevations"
            )
        edges = np.concatenate([[0.0], np.cumsum(lengths)])
        inner = edges[1:-1]

        def index(s):
            return np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(lengths) - 1)

        elevation = 0.0 if not np.any(elevs) else (lambda s: elevs[index(s)])
        m = cls(
            lambda s: mags[index(s)],
            lambda s: angs[index(s)],
            elevation,
            breakpoints=inner,
            label=label,
        )
        m.segment_edges = edges
        m.segment_magnitudes = mags
        m.segment_angles = angs
        m.segment_elevations = elevs
        return m

    def __repr__(self):
        if self.is_planar:
            extra = ""
        elif hasattr(self, "segment_elevations"):
            extra = f"elevations={self.segment_elevations.tolist()!r}"
        else:
            extra = f"elevation={self._elevation!r}"
        if self.label:
            return f"Magnetization({self.label}{'; ' + extra if extra else ''})"
        return (
            f"Magnetization(magnitude={self._magnitude!r}, angle={self._angle!r}"
            f"{', ' + extra if extra else ''})"
        )
