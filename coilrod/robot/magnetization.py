"""Magnetization profiles along the rod: magnitude |M|(s) in A/m and angle theta_m(s) in rad.

The angle is measured from the local tangent, in the bending plane (counter-clockwise about z).
In the reference (straight, along +x) configuration the magnetization vector is
``|M| (cos theta_m, sin theta_m, 0)``; in the deformed configuration it is rotated with the
cross-section, ``m = R(theta) M``.
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
        theta_m in rad from the local tangent, constant or function of ``s`` (m).
    breakpoints : sequence of float, optional
        Arc lengths (m) where the profile jumps; solvers place nodes and element boundaries there.

    Examples
    --------
    >>> import numpy as np
    >>> m = Magnetization(magnitude=128e3, angle=0.0)
    >>> m.vector(np.array([0.0, 0.01]))
    array([[128000.,      0.],
           [128000.,      0.]])
    """

    def __init__(
        self,
        magnitude: Profile = 0.0,
        angle: Profile = 0.0,
        breakpoints: Sequence[float] = (),
        label: str = "",
    ):
        self._magnitude = _check_profile(magnitude, "magnitude")
        self._angle = _check_profile(angle, "angle")
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
        """True if both magnitude and angle are constants."""
        return not (callable(self._magnitude) or callable(self._angle))

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

    def vector(self, s) -> np.ndarray:
        """Body-frame magnetization (tangential, normal) components, shape (n, 2), A/m."""
        s = np.atleast_1d(as_array(s, "s"))
        mag = self.magnitude(s)
        ang = self.angle(s)
        return np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)

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

        Examples
        --------
        >>> m = Magnetization.segments([0.02, 0.02], [100e3, 200e3], [0.0, 1.0])
        >>> m.magnitude(np.array([0.01, 0.03])).tolist()
        [100000.0, 200000.0]
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
        if not (len(lengths) == len(mags) == len(angs)):
            raise ValueError(
                "segments need as many magnitudes and angles as lengths; got "
                f"{len(lengths)} lengths, {len(mags)} magnitudes, {len(angs)} angles"
            )
        edges = np.concatenate([[0.0], np.cumsum(lengths)])
        inner = edges[1:-1]

        def index(s):
            return np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(lengths) - 1)

        m = cls(lambda s: mags[index(s)], lambda s: angs[index(s)], breakpoints=inner, label=label)
        m.segment_edges = edges
        m.segment_magnitudes = mags
        m.segment_angles = angs
        return m

    def __repr__(self):
        if self.label:
            return f"Magnetization({self.label})"
        return f"Magnetization(magnitude={self._magnitude!r}, angle={self._angle!r})"
