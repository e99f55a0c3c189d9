"""Permanent magnets: a point dipole and axially magnetised cylinders and rings.

Tiers as for coils (STYLE.md): :func:`solenoid_field` is the kernel (the field of a cylindrical
current sheet in its own frame, no checks); the classes place it (position and orientation),
handle the axis and the edges, and validate once.

A cylinder uniformly magnetised along its axis with polarization ``J`` (T; ``J = mu0 M``, the
remanence of the material) has the field of its bound surface current ``K = J / mu0`` (A/m)
on the side: a finite solenoid, whose B inside and outside is the closed form of Derby & Olbert,
"Cylindrical magnets and ideal solenoids", Am. J. Phys. 78 (2010) 229, with Bulirsch's
generalised complete elliptic integral ``cel``.  Its derivative along the axis is exact
without a new closed form: moving the sheet along its axis only moves its end rings, so
``dB/dz`` is the field of two circular loops of current ``+K`` at the bottom and ``-K`` at the
top (:class:`coils.CoaxialCoils`), and curl B = div B = 0 give the radial derivatives from it
and from B.  So the hessian: its entries with an axial index are the end loops' gradient,
the rest follow from axisymmetry, div B = 0 and its symmetry in all three indices
(``CylinderMagnet._fields``).  A ring (hollow cylinder) is two sheets of opposite currents.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.constants import mu_0

from ._immutable import sealed
from ._validate import _show, as_array, as_axis, as_vector, finite_scalar, positive
from .coaxial import CoaxialCoils, frame_from_axis
from .dipoles import dipole_sum
from .field import AccumulatedField, OnePassField

__all__ = [
    "Dipole",
    "CylinderMagnet",
    "CuboidMagnet",
    "solenoid_field",
    "cuboid_field",
    "as_rotation",
]

#: A point within this fraction of the radius of an edge circle is "on the edge".
ON_EDGE = 1e-9
#: Below this fraction of the radius from the axis, B_rho / rho takes its axis limit (whose
#: error is O(rho^2) relative: the kernel keeps B_rho's relative precision down to the axis).
NEAR_AXIS = 1e-8
#: Below this fraction of the radius from the axis, the hessian's radial term takes its axis
#: limit (error O(rho^3), against the cancellation eps radius / rho of the general form).
HESSIAN_NEAR_AXIS = 1e-4
#: Beyond this many half-diagonals (``hypot(radius, length / 2)`` of a cylinder, ``|size| / 2``
#: of a cuboid) from a magnet's centre its field is a Gauss-Legendre sum over the magnet (loops
#: of a cylinder's sheets, dipoles of a cuboid's volume) instead of the closed forms, whose
#: differences of nearly equal terms lose about ``(distance / size)^3`` ulps (all digits of a
#: cuboid's B by ``1e5`` sizes).  The sums converge like ``(size / distance)^(2 m)``: at this
#: distance the orders below are exact to rounding (about ``1e-14`` relative).
FAR = 8.0
#: Gauss-Legendre points along a cylinder's sheet (loops per sheet) beyond :data:`FAR`.
FAR_LOOPS = 8
#: Gauss-Legendre points per axis of a cuboid (dipoles: their cube) beyond :data:`FAR`.
FAR_DIPOLES = 7


def as_rotation(orientation, name: str = "orientation") -> np.ndarray:
    """A rotation matrix (3, 3) (local -> global, columns the local axes) from None (identity),
    a ``scipy.spatial.transform.Rotation`` or an array-like (3, 3) proper rotation."""
    if orientation is None:
        return np.eye(3)
    if hasattr(orientation, "as_matrix"):
        mat = np.asarray(orientation.as_matrix(), dtype=float)
        if mat.shape != (3, 3):
            raise ValueError(f"{name} must be a single rotation; got {mat.shape[:-2]} of them")
        return mat
    mat = as_array(orientation, name, (3, 3))
    if np.abs(mat.T @ mat - np.eye(3)).max() > 1e-9 or np.linalg.det(mat) < 0:
        raise ValueError(
            f"{name} must be a rotation matrix (orthonormal, det +1) or a scipy Rotation; "
            f"got {_show(mat.tolist())}"
        )
    return mat


# -- tier 1: kernels -------------------------------------------------------------------------------
def _cel(kc, p, c, s, one_minus_kc=None):
    """Bulirsch's generalised complete elliptic integral, vectorised (kc != 0, p >= 0):
    integral_0^{pi/2} (c cos^2 + s sin^2) / ((cos^2 + p sin^2) sqrt(cos^2 + kc^2 sin^2)).

    ``one_minus_kc`` (only with ``p = c = 1, s = -1``, kc > 0): ``1 - kc`` computed without
    cancellation; the integral is then O(1 - kc) and keeps its relative precision as
    ``kc -> 1`` (its first step's ``2 (kc - 1)`` is the one cancellation of the recursion)."""
    kc, p, c, s = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (kc, p, c, s)))
    k = np.abs(kc)
    em = np.ones_like(k)
    pos = p > 0
    pp = np.where(pos, np.sqrt(np.where(pos, p, 1.0)), 0.0)
    ss = np.where(pos, s / np.where(pos, pp, 1.0), s)
    cc = c.copy()
    if not np.all(pos):  # p <= 0 (here p = 0: on the cylinder's side surface)
        p0 = np.where(pos, 0.0, p)  # the entries p > 0 take the other branch: no 0/0 here
        f = kc * kc
        q = (1.0 - f) * (s - c * p0)
        g = 1.0 - p0
        f2 = f - p0
        pn = np.sqrt(f2 / g)
        cn = (c - s) / g
        sn = -q / (g * g * pn) + cn * pn
        pp = np.where(pos, pp, pn)
        cc = np.where(pos, cc, cn)
        ss = np.where(pos, ss, sn)
    f = cc
    cc = cc + ss / pp
    g = k / pp
    ss = 2.0 * (ss + f * g) if one_minus_kc is None else -2.0 * one_minus_kc
    pp = g + pp
    g = em
    em = k + em
    kk = k
    for _ in range(60):
        if np.all(np.abs(g - k) <= g * 1e-9):
            break
        k = 2.0 * np.sqrt(kk)
        kk = k * em
        f = cc
        cc = cc + ss / pp
        g = kk / pp
        ss = 2.0 * (ss + f * g)
        pp = g + pp
        g = em
        em = k + em
    return 0.5 * math.pi * (ss + cc * em) / (em * (em + pp))


def solenoid_field(rho, z, radius: float, half_height: float, K: float):
    """B of a cylindrical current sheet in its frame (Derby & Olbert 2010), tier 1.

    Parameters
    ----------
    rho, z : ndarray, shape (n,)
        Cylindrical coordinates about the sheet's axis from its centre, m (not on an edge).
    radius, half_height : float
        The sheet's radius and half its height, m.
    K : float
        Sheet current per unit height, A/m (counter-clockwise about +z; ``J / mu0`` for a
        magnet of polarization J).

    Returns
    -------
    B_rho, B_z : ndarray, shape (n,)
        T.
    """
    a, b = radius, half_height
    B0 = mu_0 * K / math.pi
    ap = a + rho
    gamma = (a - rho) / ap
    out_r = np.zeros_like(rho)
    out_z = np.zeros_like(rho)
    for sign in (1.0, -1.0):
        zz = z + sign * b
        root = np.sqrt(zz * zz + ap * ap)
        alpha = a / root
        beta = zz / root
        kc = np.sqrt((zz * zz + (a - rho) ** 2) / (zz * zz + ap * ap))
        one_minus = 4.0 * a * rho / ((zz * zz + ap * ap) * (1.0 + kc))  # (1 - kc^2) / (1 + kc)
        out_r += sign * alpha * _cel(kc, 1.0, 1.0, -1.0, one_minus)
        out_z += sign * beta * _cel(kc, gamma * gamma, 1.0, gamma)
    return B0 * out_r, B0 * a / ap * out_z


def _edge_ratio(t1, t2, rho2, r1, r2):
    """(t1/r1 - t2/r2) / rho2, stable (t1 < t2)."""
    same = t1 * t2 > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        direct = (t1 / r1 - t2 / r2) / rho2
        stable = (t1 * t1 - t2 * t2) / (r1 * r2 * (t1 * r2 + t2 * r1))
    return np.where(same, stable, direct)


def _edge_ratio_slope(t1, t2, rho2, r1, r2):
    """d/d(rho2) of :func:`_edge_ratio` (t1 < t2), stable: with both ends on one side
    ``D = g(t2) - g(t1)``, ``g = 1 / (r (r + t))`` (``-1 / (r (r - t))`` below zero), whose
    slope ``-(2 r + t) / (2 r^3 (r + t)^2)`` has no cancellation near the edge's line."""
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = _ratio_end_slope(t2, r2) - _ratio_end_slope(t1, r1)
        neg = _ratio_end_slope(-t1, r1) - _ratio_end_slope(-t2, r2)
        direct = (
            t2 * (rho2 + 2 * r2 * r2) / (2 * r2**3) - t1 * (rho2 + 2 * r1 * r1) / (2 * r1**3)
        ) / (rho2 * rho2)
    return np.where(t1 > 0, pos, np.where(t2 < 0, neg, direct))


def _ratio_end_slope(t, r):
    return -(2 * r + t) / (2 * r**3 * (r + t) ** 2)


def _edge_log(t1, t2, rho2, r1, r2):
    """ln(t2 + r2) - ln(t1 + r1), stable (t1 < t2)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = np.log((t2 + r2) / (t1 + r1))
        neg = np.log((r1 - t1) / (r2 - t2))
        mid = np.log((t2 + r2) * (r1 - t1) / rho2)
    return np.where(t1 >= 0, pos, np.where(t2 <= 0, neg, mid))


def cuboid_field(p, h, hessian: bool = False):
    """B, gradient (and hessian) of a box magnetised along its z axis with unit
    polarization (tier 1).

    Parameters
    ----------
    p : ndarray, shape (n, 3)
        Points in the box's frame (centre at the origin, edges along the axes), m.
    h : ndarray, shape (3,)
        Half side lengths, m.
    hessian : bool
        Also return the hessian.

    Returns
    -------
    B : ndarray, shape (n, 3)
        T per tesla of polarization (``mu0 H``, plus the polarization inside).
    G : ndarray, shape (n, 3, 3)
        ``dB_i/dx_j``, T/m per tesla.
    H : ndarray, shape (n, 3, 3, 3)
        ``d2B_i/(dx_j dx_l)``, T/m^2 per tesla (only if ``hessian``).

    Notes
    -----
    The field of the charges ``+-M`` on the faces ``z = +-h_z``: per face and corner
    ``(U, V, W)`` (point minus corner) ``B_x ~ -ln(V + r)``, ``B_y ~ -ln(U + r)``,
    ``B_z ~ atan(U V / (W r))``, summed with the corners' signs; the gradient differentiates
    them in closed form (rational in U, V, W, r) and takes the normal derivatives from
    curl B = div B = 0.  The hessian differentiates the gradient's terms once more
    (``d(1/r) = -(U, V, W) / r^3`` for the mixed entries, the slope of the edge ratio for the
    others) and takes the entries with two normal indices from its trace.  Differences of
    logarithms, of ``t / r`` and of its slope along an edge are written without cancellation
    near the edges' lines.  A point on an edge gives non-finite values.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return _cuboid_terms(p, h, hessian)


def _cuboid_terms(p, h, want_H=False):
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    n = p.shape[0]
    U1, U2 = x - h[0], x + h[0]
    V1, V2 = y - h[1], y + h[1]
    B = np.zeros((n, 3))
    G = np.zeros((n, 3, 3))
    # the hessian's entries xxx, xxy, xxz, xyy, xyz, yyy, yyz (the rest: symmetry and trace)
    Hc = np.zeros((7, n)) if want_H else None
    for sig, f in ((1.0, h[2]), (-1.0, -h[2])):
        W = z - f
        W2 = W * W
        bx = by = bz = gxx = gyy = gxy = gxz = gyz = 0.0
        hxxx = hxxy = hxxz = hxyy = hxyz = hyyy = hyyz = 0.0
        for sU, U in ((-1.0, U1), (1.0, U2)):
            rho2 = U * U + W2
            r1 = np.sqrt(rho2 + V1 * V1)
            r2 = np.sqrt(rho2 + V2 * V2)
            D = _edge_ratio(V1, V2, rho2, r1, r2)
            bx = bx - sU * _edge_log(V1, V2, rho2, r1, r2)
            gxx = gxx - sU * U * D
            gxz = gxz - sU * W * D
            if want_H:
                D2 = 2.0 * _edge_ratio_slope(V1, V2, rho2, r1, r2)  # d D / d(U or W) / (U or W)
                hxxx = hxxx - sU * (D + U * U * D2)
                hxxz = hxxz - sU * U * W * D2
            for sV, V, r in ((-1.0, V1, r1), (1.0, V2, r2)):
                # in the face's plane (W = 0) the limit from outside the box (W -> sig 0):
                # B_z, normal to the charged face, is continuous across it
                UV = U * V
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = np.where(
                        W == 0,
                        np.where(UV == 0, 0.0, sig * np.copysign(0.5 * math.pi, UV)),
                        np.arctan(UV / (W * r)),
                    )
                bz = bz + sU * sV * t
                gxy = gxy - sU * sV / r
                if want_H:
                    r3 = sU * sV / (r * r * r)
                    hxxy = hxxy + U * r3
                    hxyy = hxyy + V * r3
                    hxyz = hxyz + W * r3
        for sV, V in ((-1.0, V1), (1.0, V2)):
            rho2 = V * V + W2
            r1 = np.sqrt(rho2 + U1 * U1)
            r2 = np.sqrt(rho2 + U2 * U2)
            D = _edge_ratio(U1, U2, rho2, r1, r2)
            by = by - sV * _edge_log(U1, U2, rho2, r1, r2)
            gyy = gyy - sV * V * D
            gyz = gyz - sV * W * D
            if want_H:
                D2 = 2.0 * _edge_ratio_slope(U1, U2, rho2, r1, r2)
                hyyy = hyyy - sV * (D + V * V * D2)
                hyyz = hyyz - sV * V * W * D2
        B[:, 0] += sig * bx
        B[:, 1] += sig * by
        B[:, 2] += sig * bz
        G[:, 0, 0] += sig * gxx
        G[:, 1, 1] += sig * gyy
        G[:, 0, 1] += sig * gxy
        G[:, 1, 0] += sig * gxy
        G[:, 0, 2] += sig * gxz
        G[:, 2, 0] += sig * gxz
        G[:, 1, 2] += sig * gyz
        G[:, 2, 1] += sig * gyz
        if want_H:
            Hc += sig * np.array(
                np.broadcast_arrays(hxxx, hxxy, hxxz, hxyy, hxyz, hyyy, hyyz), dtype=float
            )
    B /= 4 * math.pi
    G /= 4 * math.pi
    G[:, 2, 2] = -G[:, 0, 0] - G[:, 1, 1]
    inside = np.all(np.abs(p) < h, axis=1)
    B[:, 2] += inside
    if not want_H:
        return B, G
    xxx, xxy, xxz, xyy, xyz, yyy, yyz = Hc / (4 * math.pi)
    comps = {
        (0, 0, 0): xxx,
        (0, 0, 1): xxy,
        (0, 0, 2): xxz,
        (0, 1, 1): xyy,
        (0, 1, 2): xyz,
        (1, 1, 1): yyy,
        (1, 1, 2): yyz,
        (0, 2, 2): -xxx - xyy,  # H_iik = 0
        (1, 2, 2): -xxy - yyy,
        (2, 2, 2): -xxz - yyz,
    }
    H = np.empty((n, 3, 3, 3))
    for (a, b, c), val in comps.items():
        for idx in {(a, b, c), (a, c, b), (b, a, c), (b, c, a), (c, a, b), (c, b, a)}:
            H[:, idx[0], idx[1], idx[2]] = val
    return B, G, H


# -- public sources -------------------------------------------------------------------------------
class Dipole(AccumulatedField):
    """A point magnetic dipole.

    Parameters
    ----------
    moment : array-like, shape (3,)
        Magnetic moment, A m^2 (a magnet's ``M V``: magnetization M in A/m, volume V in m^3).
    center : array-like, shape (3,)
        Position, m.

    Notes
    -----
    ``B = mu0 / (4 pi) (3 r (m . r) - m r^2) / r^5`` with ``r = x - center``; B, the gradient
    and the hessian are exact (:mod:`coils.dipoles`).  A point at the centre is refused.

    Examples
    --------
    >>> from coils import Dipole
    >>> d = Dipole((0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    >>> round(float(d.B([0.0, 0.0, 0.1])[0, 2]) * 1e3, 9)   # 2 mu0 m / (4 pi z^3), mT
    0.2
    """

    _immutable = True

    def __init__(self, moment, center=(0.0, 0.0, 0.0)):
        self.moment = sealed(as_vector(moment, "moment"))
        self.center = sealed(as_vector(center, "center"))
        self._pos = sealed(self.center[None, :])
        self._mom = sealed(mu_0 / (4 * math.pi) * self.moment[None, :])  # T m^3

    @property
    def length_scale(self) -> float:
        return 1.0

    def _add_to(self, pts, B, G, H, factor):
        hit = dipole_sum(np.ascontiguousarray(pts), self._pos, factor * self._mom, 0.0, B, G, H)
        if hit >= 0:
            raise ValueError(
                f"points[{hit}] = {pts[hit].tolist()} m is at the dipole's centre: its field is "
                f"infinite there"
            )

    def __repr__(self):
        return f"Dipole(moment={self.moment.tolist()}, center={self.center.tolist()})"


class CylinderMagnet(OnePassField):
    """An axially magnetised cylinder or ring (hollow cylinder) permanent magnet.

    Parameters
    ----------
    diameter : float
        Outer diameter, m.
    length : float
        Length along the magnetisation axis, m.
    magnetization : float
        Magnetization M along ``axis``, A/m (``B_r / mu0`` for a rigid magnet of remanence
        ``B_r``: 1.15e6 A/m for N52's 1.45 T; negative: magnetised along ``-axis``).
    center : array-like, shape (3,)
        Position of the magnet's centre, m.
    axis : {"x", "y", "z"}, optionally signed ("-y"), or array-like, shape (3,)
        Magnetisation direction (normalised); default "z".  Give it or ``orientation``.
    inner_diameter : float
        Bore diameter of a ring, m (0: a full cylinder; below ``diameter``).
    orientation : scipy Rotation or array-like (3, 3), optional
        The pose's rotation from the magnet's frame (magnetisation along its z) to the global
        one, instead of ``axis``.

    Notes
    -----
    B is the Derby & Olbert closed form of the side sheets (:func:`solenoid_field`); the
    gradient and the hessian are exact from it and the end loops (:mod:`coils.magnets`),
    symmetric and traceless to rounding.  Inside the
    material B includes the polarization (``B = mu0 (H + M)``), as magpylib's.  Points on an
    edge circle are refused; on the side surface B is discontinuous and the value returned
    is the mean of its two sides.  Far away the field is that of :meth:`dipole`.

    Examples
    --------
    >>> from coils import CylinderMagnet
    >>> m = CylinderMagnet(diameter=10e-3, length=10e-3, magnetization=1e6)
    >>> round(float(m.B([0.0, 0.0, 0.0])[0, 2]), 6)   # mu0 M L / (2 sqrt(R^2 + L^2/4)), T
    0.888577
    """

    _immutable = True
    _caches = ("_loops", "_far_loops")

    def __init__(
        self,
        diameter,
        length,
        magnetization,
        center=(0.0, 0.0, 0.0),
        axis=None,
        *,
        inner_diameter=0.0,
        orientation=None,
    ):
        self.diameter = positive(diameter, "diameter")
        self.length = positive(length, "length")
        self.magnetization = finite_scalar(magnetization, "magnetization")
        self.inner_diameter = finite_scalar(inner_diameter, "inner_diameter")
        if not 0.0 <= self.inner_diameter < self.diameter:
            raise ValueError(
                f"inner_diameter must be in [0, diameter = {self.diameter}) m; got "
                f"{self.inner_diameter}"
            )
        self.center = sealed(as_vector(center, "center"))
        if axis is not None and orientation is not None:
            raise ValueError("give axis or orientation, not both (orientation includes the axis)")
        if orientation is None:
            rotation = frame_from_axis(as_axis("z" if axis is None else axis))
        else:
            rotation = as_rotation(orientation)
        self.rotation = sealed(rotation)
        self._loops = None
        self._far_loops = None

    @property
    def radius(self) -> float:
        """Outer radius, m."""
        return 0.5 * self.diameter

    @property
    def inner_radius(self) -> float:
        """Bore radius, m (0 for a full cylinder)."""
        return 0.5 * self.inner_diameter

    @property
    def height(self) -> float:
        """The length along the axis, m."""
        return self.length

    @property
    def polarization(self) -> float:
        """``mu0 M``, T."""
        return mu_0 * self.magnetization

    @property
    def axis(self) -> np.ndarray:
        """Magnetisation direction (unit, global), shape (3,)."""
        return self.rotation[:, 2].copy()

    @property
    def volume(self) -> float:
        """m^3."""
        return math.pi * (self.radius**2 - self.inner_radius**2) * self.height

    @property
    def length_scale(self) -> float:
        return min(self.height, self.radius - self.inner_radius)

    def dipole(self) -> Dipole:
        """The point dipole of the same moment ``M V axis`` (A m^2) at the centre: the far
        field, to O((size / distance)^2) relative."""
        return Dipole(self.magnetization * self.volume * self.axis, self.center)

    def _sheets(self):
        K = self.magnetization
        sheets = [(self.radius, K)]
        if self.inner_radius > 0:
            sheets.append((self.inner_radius, -K))
        return sheets

    def _end_loops(self) -> CoaxialCoils:
        if self._loops is None:
            b = 0.5 * self.height
            fil = []
            for a, K in self._sheets():
                fil += [(-b, a, K), (b, a, -K)]
            self._set_cache("_loops", CoaxialCoils(fil, axis=self.axis, center=self.center))
        return self._loops

    def _local(self, pts):
        local = (pts - self.center) @ self.rotation
        rho = np.hypot(local[:, 0], local[:, 1])
        b = 0.5 * self.height
        for a, _ in self._sheets():
            edge = np.hypot(rho - a, np.abs(local[:, 2]) - b) <= ON_EDGE * a
            if edge.any():
                k = int(np.nonzero(edge)[0][0])
                raise ValueError(
                    f"points[{k}] = {pts[k].tolist()} m is on an edge circle of the magnet "
                    f"(radius {a} m): its field gradient is infinite there"
                )
        return local, rho

    def _far_field(self) -> CoaxialCoils:
        """The sheets as :data:`FAR_LOOPS` Gauss-Legendre loops each, in the magnet's frame."""
        if self._far_loops is None:
            b = 0.5 * self.height
            x, w = np.polynomial.legendre.leggauss(FAR_LOOPS)
            fil = [
                (b * xi, a, K * b * wi)
                for a, K in self._sheets()
                for xi, wi in zip(x, w, strict=True)
            ]
            self._set_cache("_far_loops", CoaxialCoils(fil, axis="z"))
        return self._far_loops

    def _B_local(self, local, rho):
        """``B_rho`` and ``B_z`` (T) at points in the magnet's frame: Derby & Olbert's closed
        form near the magnet, the sheets' loop quadrature beyond :data:`FAR` (where the closed
        form's cancellation grows like the cube of the distance)."""
        Br = np.zeros_like(rho)
        Bz = np.zeros_like(rho)
        far = (
            np.einsum("ij,ij->i", local, local)
            > (FAR * math.hypot(self.radius, 0.5 * self.height)) ** 2
        )
        near = ~far
        for a, K in self._sheets():
            r, z = solenoid_field(rho[near], local[near, 2], a, 0.5 * self.height, K)
            Br[near] += r
            Bz[near] += z
        if far.any():
            Bf = self._far_field().B(local[far])
            rf = rho[far]
            safe = np.where(rf > 0, rf, 1.0)
            Br[far] = np.where(
                rf > 0, (local[far, 0] * Bf[:, 0] + local[far, 1] * Bf[:, 1]) / safe, 0.0
            )
            Bz[far] = Bf[:, 2]
        return Br, Bz

    def _B(self, pts):
        local, rho = self._local(pts)
        Br, Bz = self._B_local(local, rho)
        safe = np.where(rho > 0, rho, 1.0)
        Bl = np.column_stack([Br * local[:, 0] / safe, Br * local[:, 1] / safe, Bz])
        return Bl @ self.rotation.T

    def _fields(self, pts, want_H: bool):
        """B (n, 3) T, gradient (n, 3, 3) T/m and, if ``want_H``, hessian (n, 3, 3, 3) T/m^2
        (else None), global frame.

        In the magnet's frame (axis z, ``n = (x, y) / rho``): the end loops' field is d/dz of
        B, so every hessian entry with a z index is an entry of the loops' gradient ``L``
        (``H_ijz = dL_i/dx_j``, H symmetric in all three indices).  Axisymmetry leaves the
        in-plane entries ``H_abc = p (d_ab n_c + d_ac n_b + d_bc n_a - 4 n_a n_b n_c)
        - e n_a n_b n_c`` with ``e = L_az n_a`` (tracelessness) and ``p = rho q1``,
        ``q1 = (dQ/drho) / rho`` of ``Q = B_rho / rho``: from div B = 0,
        ``p = -(2 Q + dBz/dz) / rho``, and below ``HESSIAN_NEAR_AXIS`` radius its axis limit
        ``rho d3Bz/dz3 / 8`` (the loops' hessian).
        """
        local, rho = self._local(pts)
        Br, Bz = self._B_local(local, rho)
        loops = self._end_loops()
        R = self.rotation
        if want_H:
            dz, GL, HL = loops.B_gradient_hessian(pts)
        else:
            dz, GL = loops.B_and_gradient(pts)
        # d/dz of the local field: the end loops (exact), in the magnet's frame
        dz = dz @ R
        w = dz[:, 2]  # dBz/dz
        zero = rho == 0.0
        near = rho < NEAR_AXIS * self.radius
        safe = np.where(zero, 1.0, rho)
        u = np.where(near, -0.5 * w, Br / safe)  # B_rho / rho (its axis limit -w/2)
        c = np.where(zero, 1.0, local[:, 0] / safe)
        s = np.where(zero, 0.0, local[:, 1] / safe)
        n = pts.shape[0]
        G = np.empty((n, 3, 3))
        drr = -w - u  # dB_rho/drho (div B = 0)
        G[:, 0, 0] = drr * c * c + u * s * s
        G[:, 1, 1] = drr * s * s + u * c * c
        G[:, 0, 1] = G[:, 1, 0] = (drr - u) * s * c
        G[:, :, 2] = dz
        G[:, 2, :2] = dz[:, :2]  # curl B = 0
        Bl = np.column_stack([Br * c, Br * s, Bz])
        B = Bl @ R.T
        G = np.einsum("ia,kab,jb->kij", R, G, R)
        if not want_H:
            return B, G, None
        L = np.einsum("ai,kab,bj->kij", R, GL, R)  # the loops' gradient, magnet frame
        L = 0.5 * (L + L.transpose(0, 2, 1))
        Hl = np.empty((n, 3, 3, 3))
        Hl[:, 2, :, :] = L
        Hl[:, :, 2, :] = L
        Hl[:, :, :, 2] = L
        e = L[:, 0, 2] * c + L[:, 1, 2] * s
        p = -(2.0 * Br / safe + w) / safe
        close = rho < HESSIAN_NEAR_AXIS * self.radius
        if close.any():
            ax = self.axis
            d3 = np.einsum("kabc,a,b,c->k", HL[close], ax, ax, ax)  # d3Bz/dz3 on the axis
            p[close] = rho[close] * d3 / 8.0
        nv = (c, s)
        for a in range(2):
            for b in range(a, 2):
                for k in range(b, 2):
                    val = p * ((a == b) * nv[k] + (a == k) * nv[b] + (b == k) * nv[a])
                    val = val - (4.0 * p + e) * nv[a] * nv[b] * nv[k]
                    for i, j, m in {
                        (a, b, k),
                        (a, k, b),
                        (b, a, k),
                        (b, k, a),
                        (k, a, b),
                        (k, b, a),
                    }:
                        Hl[:, i, j, m] = val
        Hg = np.einsum("kabc,ia,jb,lc->kijl", Hl, R, R, R, optimize=True)
        return B, G, Hg

    def __repr__(self):
        ring = f", inner_diameter={self.inner_diameter!r}" if self.inner_diameter else ""
        return (
            f"CylinderMagnet(diameter={self.diameter!r}, length={self.length!r}, "
            f"magnetization={self.magnetization!r}, center={self.center.tolist()}, "
            f"axis={np.round(self.axis, 12).tolist()}{ring})"
        )


#: Axis orders putting magnetisation axis 0, 1, 2 on the kernel's z (cyclic: proper rotations).
_CYCLIC = (np.array([1, 2, 0]), np.array([2, 0, 1]), np.array([0, 1, 2]))


class CuboidMagnet(OnePassField):
    """A uniformly magnetised rectangular block (cuboid) permanent magnet.

    Parameters
    ----------
    size : array-like, shape (3,)
        Side lengths along the magnet's x, y, z axes, m.
    magnetization : array-like, shape (3,)
        Magnetization M in the magnet's frame, A/m (any direction; ``B_r / mu0`` in size).
    center : array-like, shape (3,)
        Position of the centre, m.
    orientation : scipy Rotation or array-like (3, 3), optional
        Rotation from the magnet's frame to the global one (default: aligned).

    Notes
    -----
    B and the gradient are exact closed forms (:func:`cuboid_field`, one per magnetisation
    component), inside the material as well (``B = mu0 (H + M)``, as magpylib's), and so is
    the hessian (symmetric and traceless to rounding).  A point on an edge of a charged
    face (one not parallel to M) is refused; on a face the outside value is returned (B is
    discontinuous across a face parallel to M; its normal part is continuous across a charged
    face).

    Examples
    --------
    >>> from coils import CuboidMagnet
    >>> m = CuboidMagnet((10e-3, 10e-3, 10e-3), (0.0, 0.0, 1e6))
    >>> round(float(m.B([0.0, 0.0, 10e-3])[0, 2]), 6)  # (J/pi)[atan(ab/(z1 r1))-atan(ab/(z2 r2))]
    0.169373
    """

    _immutable = True

    def __init__(self, size, magnetization, center=(0.0, 0.0, 0.0), orientation=None):
        size = as_vector(size, "size")
        if not np.all(size > 0):
            raise ValueError(f"size must be three positive lengths (m); got {size.tolist()}")
        self.size = sealed(size)
        self.magnetization = sealed(as_vector(magnetization, "magnetization"))
        self.center = sealed(as_vector(center, "center"))
        self.rotation = sealed(as_rotation(orientation))

    @property
    def volume(self) -> float:
        """m^3."""
        return float(np.prod(self.size))

    @property
    def length_scale(self) -> float:
        return float(self.size.min())

    def dipole(self) -> Dipole:
        """The point dipole of moment ``M V`` (global frame, A m^2) at the centre."""
        return Dipole(self.rotation @ self.magnetization * self.volume, self.center)

    def _fields(self, pts, want_H: bool):
        """B (n, 3) T, gradient (n, 3, 3) T/m and hessian (n, 3, 3, 3) T/m^2 (None unless
        ``want_H``), global frame."""
        local = (pts - self.center) @ self.rotation
        h = 0.5 * self.size
        n = pts.shape[0]
        B = np.zeros((n, 3))
        G = np.zeros((n, 3, 3))
        H = np.zeros((n, 3, 3, 3)) if want_H else None
        far = np.einsum("ij,ij->i", local, local) > (FAR * float(np.linalg.norm(h))) ** 2
        near = np.nonzero(~far)[0]
        for k in range(3):
            if self.magnetization[k] == 0.0 or near.size == 0:
                continue
            perm = _CYCLIC[k]
            out = cuboid_field(local[near][:, perm], h[perm], want_H)
            J = mu_0 * self.magnetization[k]
            B[near[:, None], perm] += J * out[0]
            G[near[:, None, None], perm[:, None], perm[None, :]] += J * out[1]
            if want_H:
                H[
                    near[:, None, None, None],
                    perm[:, None, None],
                    perm[None, :, None],
                    perm[None, None, :],
                ] += J * out[2]
        if far.any():
            # the volume's dipole density M as a Gauss-Legendre sum (see FAR)
            x, w = np.polynomial.legendre.leggauss(FAR_DIPOLES)
            pos = np.stack(np.meshgrid(x, x, x, indexing="ij"), -1).reshape(-1, 3) * h
            wts = np.einsum("i,j,k->ijk", w, w, w).reshape(-1) * float(np.prod(h))
            mom = mu_0 / (4 * math.pi) * wts[:, None] * self.magnetization[None, :]
            m = int(far.sum())
            Bf, Gf = np.zeros((m, 3)), np.zeros((m, 3, 3))
            Hf = np.zeros((m, 3, 3, 3)) if want_H else None
            dipole_sum(np.ascontiguousarray(local[far]), pos, mom, 0.0, Bf, Gf, Hf)
            B[far], G[far] = Bf, Gf
            if want_H:
                H[far] = Hf
        bad = ~(np.isfinite(B).all(axis=1) & np.isfinite(G).all(axis=(1, 2)))
        if want_H:
            bad |= ~np.isfinite(H).all(axis=(1, 2, 3))
        if bad.any():
            k = int(np.nonzero(bad)[0][0])
            raise ValueError(
                f"points[{k}] = {pts[k].tolist()} m is on an edge of the cuboid magnet: its "
                f"field is singular there"
            )
        R = self.rotation
        B = B @ R.T
        G = np.einsum("ia,kab,jb->kij", R, G, R)
        if want_H:
            H = np.einsum("kabc,ia,jb,lc->kijl", H, R, R, R, optimize=True)
        return B, G, H

    def __repr__(self):
        return (
            f"CuboidMagnet(size={self.size.tolist()}, magnetization="
            f"{self.magnetization.tolist()}, center={self.center.tolist()})"
        )
