"""The fused pass over points x filaments of one coaxial group (tier 2, compiled with numba).

For every point, in one loop, without temporaries and with every intermediate in registers:

1. ``d = point - center``.  If ``|d| > SWITCH * d_group`` (far zone) ``d`` is scaled by a power
   of two ``2^-e`` near ``1 / |d|`` (so ``|d|^2`` cannot overflow) and the invariants come from
   the group's multipole series (:func:`coils.multipole.multipole_point`); B, G, H are then
   multiplied by ``2^(-3e)``, ``2^(-4e)``, ``2^(-5e)`` (one rounding each, so a field that
   underflows becomes the correctly rounded subnormal or 0).
2. Otherwise (near zone) ``d`` is taken in units of the group's power-of-two length ``L``, checked
   against the winding cross-sections, and the filaments' invariants
   (:func:`coils.loop.loop_point`) are summed; a point within ``ON_WIRE_TOL`` of a filament stops
   the pass (the caller raises).
3. With the axis ``n``, the axial coordinate ``z = d . n``, the radial vector ``r = d - z n``,
   ``u = r . r`` and the invariants of :mod:`coils.loop`, the field in the global frame is
   (``dB_rho/drho = Q + u q1``, curl B = 0, div B = 0; every term regular on the axis)::

       B     = Q r + Bz n
       G_ij  = Q d_ij + q1 r_i r_j + b1 (r_i n_j + n_i r_j) - (3 Q + q1 u) n_i n_j
       H_ijl = (a_i d_jl + a_j d_il + a_l d_ij) + r_i A_jl + n_i C_jl,   a = q1 r + b1 n,
       A = q2 r r + d1 (n r + r n) + (c1 - q1) n n,     q2 = -(4 q1 + c1) / u  (Laplace),
       C = d1 r r + (c1 - q1) (r n + n r) - (5 b1 + d1 u) n n,

   which in the coil frame (``n = e_z``, ``r = (x, y, 0)``) reads ``B = (Q x, Q y, Bz)``,
   ``G_xx = Q + q1 x^2``, ``G_xz = b1 x``, ``G_zz = -2 Q - q1 u``,
   ``H_abc = q1 (x_a d_bc + x_b d_ac + x_c d_ab) + q2 x_a x_b x_c``, ``H_zab = b1 d_ab + d1 x_a
   x_b``, ``H_zza = c1 x_a``, ``H_zzz = -2 b1 - d1 u``: no rotation matrices are needed.

The field (times ``factor``) is added to the output arrays, so a sum of groups fills one set
of arrays (callers pass zeros for a single group).  Nothing here validates input;
:class:`coils.coaxial.CoaxialCoils` does.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

from numba import njit

from .loop import loop_point
from .multipole import multipole_point

__all__ = ["coaxial_field", "WANT_B", "WANT_G", "WANT_H"]

WANT_B, WANT_G, WANT_H = 1, 2, 4

# slots of the error array
ERR_ON_WIRE, ERR_NOT_FINITE, ERR_OVERFLOW, ERR_WINDING = 0, 1, 2, 3


@njit(cache=True, error_model="numpy")
def _global(rx, ry, rz, nx, ny, nz, u, Q, Bz, b1, q1, q2, c1, d1, want_G, want_H):
    """The 3 + 6 + 10 distinct entries of B, G, H (module docstring, step 3; B always, G and H
    as asked, else 0); plain arithmetic and flags, so that it runs as Python on arrays too
    (:mod:`coils._vectorised`)."""
    # B
    B0 = Q * rx + Bz * nx
    B1 = Q * ry + Bz * ny
    B2 = Q * rz + Bz * nz
    # products shared by G and H: r r, (r n + n r), n n
    rr00, rr01, rr02, rr11, rr12, rr22 = rx * rx, rx * ry, rx * rz, ry * ry, ry * rz, rz * rz
    rn00, rn11, rn22 = 2.0 * rx * nx, 2.0 * ry * ny, 2.0 * rz * nz
    rn01, rn02, rn12 = rx * ny + ry * nx, rx * nz + rz * nx, ry * nz + rz * ny
    nn00, nn01, nn02, nn11, nn12, nn22 = nx * nx, nx * ny, nx * nz, ny * ny, ny * nz, nz * nz
    G00 = G01 = G02 = G11 = G12 = G22 = 0.0
    if want_G:
        gn = -3.0 * Q - q1 * u
        G00 = Q + q1 * rr00 + b1 * rn00 + gn * nn00
        G01 = q1 * rr01 + b1 * rn01 + gn * nn01
        G02 = q1 * rr02 + b1 * rn02 + gn * nn02
        G11 = Q + q1 * rr11 + b1 * rn11 + gn * nn11
        G12 = q1 * rr12 + b1 * rn12 + gn * nn12
        G22 = Q + q1 * rr22 + b1 * rn22 + gn * nn22
    H000 = H001 = H011 = H111 = H002 = H012 = H112 = H022 = H122 = H222 = 0.0
    if want_H:
        cp = c1 - q1
        hp = -5.0 * b1 - d1 * u
        a0 = q1 * rx + b1 * nx
        a1 = q1 * ry + b1 * ny
        a2 = q1 * rz + b1 * nz
        A00 = q2 * rr00 + d1 * rn00 + cp * nn00
        A01 = q2 * rr01 + d1 * rn01 + cp * nn01
        A02 = q2 * rr02 + d1 * rn02 + cp * nn02
        A11 = q2 * rr11 + d1 * rn11 + cp * nn11
        A12 = q2 * rr12 + d1 * rn12 + cp * nn12
        A22 = q2 * rr22 + d1 * rn22 + cp * nn22
        C00 = d1 * rr00 + cp * rn00 + hp * nn00
        C01 = d1 * rr01 + cp * rn01 + hp * nn01
        C02 = d1 * rr02 + cp * rn02 + hp * nn02
        C11 = d1 * rr11 + cp * rn11 + hp * nn11
        C12 = d1 * rr12 + cp * rn12 + hp * nn12
        C22 = d1 * rr22 + cp * rn22 + hp * nn22
        H000 = 3.0 * a0 + rx * A00 + nx * C00
        H001 = a1 + rx * A01 + nx * C01
        H011 = a0 + rx * A11 + nx * C11
        H111 = 3.0 * a1 + ry * A11 + ny * C11
        H002 = a2 + rx * A02 + nx * C02
        H012 = rx * A12 + nx * C12
        H112 = a2 + ry * A12 + ny * C12
        H022 = a0 + rx * A22 + nx * C22
        H122 = a1 + ry * A22 + ny * C22
        H222 = 3.0 * a2 + rz * A22 + nz * C22
    return (
        B0, B1, B2, G00, G01, G02, G11, G12, G22,
        H000, H001, H011, H111, H002, H012, H112, H022, H122, H222,
    )  # fmt: skip


@njit(cache=True, error_model="numpy", inline="always")
def _near(fil, u, rho, zl, tol2, want_B, want_G, want_H):
    """Sum of the filaments' invariants at one point (units of L); ``ok`` is False (and the
    sum incomplete) if the point is within ``sqrt(tol2)`` radius of a filament."""
    Q = Bz = b1 = q1 = c1 = d1 = 0.0
    for i in range(fil.shape[0]):
        a = fil[i, 1]
        zi = zl - fil[i, 0]
        if not ((rho - a) * (rho - a) + zi * zi) * fil[i, 4] >= tol2:
            return False, Q, Bz, b1, q1, c1, d1
        res = loop_point(a, fil[i, 2], fil[i, 3], u, rho, zi, want_B, want_G, want_H)
        Q += res[0]
        Bz += res[1]
        b1 += res[2]
        q1 += res[3]
        c1 += res[4]
        d1 += res[5]
    return True, Q, Bz, b1, q1, c1, d1


@njit(cache=True, error_model="numpy")
def _sc(x, s, ex, far):
    """``x s 2^ex`` (far zone: ``ldexp``, one rounding) or ``x s`` (near zone)."""
    return math.ldexp(x * s, ex) if far else x * s


@njit(cache=True, error_model="numpy", inline="always")
def _store_point(Bout, Gout, Hout, k, v, sB, sG, sH, eB, eG, eH, far, want_B, want_G, want_H):
    """Scale the distinct entries ``v`` (19,) and add them to row ``k`` of the outputs; False if
    a value is not finite."""
    bad = 0.0
    if want_B:
        b0 = _sc(v[0], sB, eB, far)
        b1_ = _sc(v[1], sB, eB, far)
        b2 = _sc(v[2], sB, eB, far)
        bad += (b0 + b1_ + b2) * 0.0
        Bout[k, 0] += b0
        Bout[k, 1] += b1_
        Bout[k, 2] += b2
    if want_G:
        g00 = _sc(v[3], sG, eG, far)
        g01 = _sc(v[4], sG, eG, far)
        g02 = _sc(v[5], sG, eG, far)
        g11 = _sc(v[6], sG, eG, far)
        g12 = _sc(v[7], sG, eG, far)
        g22 = _sc(v[8], sG, eG, far)
        bad += (g00 + g01 + g02 + g11 + g12 + g22) * 0.0
        Gout[k, 0] += g00
        Gout[k, 1] += g01
        Gout[k, 2] += g02
        Gout[k, 3] += g01
        Gout[k, 4] += g11
        Gout[k, 5] += g12
        Gout[k, 6] += g02
        Gout[k, 7] += g12
        Gout[k, 8] += g22
    if want_H:
        h000 = _sc(v[9], sH, eH, far)
        h001 = _sc(v[10], sH, eH, far)
        h011 = _sc(v[11], sH, eH, far)
        h111 = _sc(v[12], sH, eH, far)
        h002 = _sc(v[13], sH, eH, far)
        h012 = _sc(v[14], sH, eH, far)
        h112 = _sc(v[15], sH, eH, far)
        h022 = _sc(v[16], sH, eH, far)
        h122 = _sc(v[17], sH, eH, far)
        h222 = _sc(v[18], sH, eH, far)
        bad += (h000 + h001 + h011 + h111 + h002 + h012 + h112 + h022 + h122 + h222) * 0.0
        Hout[k, 0] += h000
        Hout[k, 1] += h001
        Hout[k, 2] += h002
        Hout[k, 3] += h001
        Hout[k, 4] += h011
        Hout[k, 5] += h012
        Hout[k, 6] += h002
        Hout[k, 7] += h012
        Hout[k, 8] += h022
        Hout[k, 9] += h001
        Hout[k, 10] += h011
        Hout[k, 11] += h012
        Hout[k, 12] += h011
        Hout[k, 13] += h111
        Hout[k, 14] += h112
        Hout[k, 15] += h012
        Hout[k, 16] += h112
        Hout[k, 17] += h122
        Hout[k, 18] += h002
        Hout[k, 19] += h012
        Hout[k, 20] += h022
        Hout[k, 21] += h012
        Hout[k, 22] += h112
        Hout[k, 23] += h122
        Hout[k, 24] += h022
        Hout[k, 25] += h122
        Hout[k, 26] += h222
    return bad == 0.0


def _source_digest() -> int:
    """A hash of the compiled sources (this module, :mod:`coils.loop`, :mod:`coils.multipole`).

    numba's on-disk cache checks only the defining file of a function; the kernel captures this
    number, so that its cache entry is replaced when a function it inlines changes too.
    """
    h = hashlib.sha256()
    for name in ("_compiled.py", "loop.py", "multipole.py"):
        try:
            h.update((Path(__file__).parent / name).read_bytes())
        except OSError:  # sources not shipped (zipped install): numba cannot cache either
            return 0
    return int.from_bytes(h.digest()[:6], "little")


def _make_kernel(digest: int):
    """The compiled pass ``coaxial_field``, its cache entry tied to ``digest``
    (:func:`_source_digest`).

    ``coaxial_field(pts, center, axis, fil, wind, beta, n0, params, flags, factor, Bout, Gout,
    Hout, err)`` adds the field of one coaxial group at many points to the outputs.

    Parameters
    ----------
    pts : ndarray, shape (n, 3)
        Global points, m.
    center, axis : ndarray, shape (3,)
        Group centre (m) and unit axis.
    fil : ndarray, shape (f, 5)
        Per filament, in units of L: ``z_offset, radius, mu0 I radius^2, mu0 I / (2 pi),
        1 / radius^2``.
    wind : ndarray, shape (w, 4)
        Winding cross-sections in units of L: ``z0, radius, width / 2, height / 2``.
    beta : ndarray, shape (N,)
        Normalised axial moments (T m^3, :func:`coils.multipole.group_moments`).
    n0 : int
        First non-zero moment.
    params : ndarray, shape (8,)
        ``1/L, 1/L (B scale), 1/L^2, 1/L^3, (SWITCH d)^2 [m^2], d [m], kappa,
        ON_WIRE_TOL^2``.
    flags : int
        ``WANT_B | WANT_G | WANT_H`` bits.
    factor : float
        Multiplies the field (current scaling of a :class:`coils.field.ScaledField`).
    Bout, Gout, Hout : ndarray, shapes (n, 3), (n, 9), (n, 27)
        Outputs (T, T/m, T/m^2), added to; unused ones may have 0 rows.
    err : ndarray of int64, shape (3 + w,)
        Filled with the first offending point index (or -1): on a filament, non-finite
        result, coordinate overflow, then one slot per winding cross-section.

    Returns
    -------
    numba dispatcher
        ``coaxial_field``; a call returns 0 if every point was evaluated, 1 if ``err`` names
        an offending point (the pass stops at the first point on a filament).
    """

    @njit(cache=True, error_model="numpy")
    def coaxial_field(
        pts, center, axis, fil, wind, beta, n0, params, flags, factor, Bout, Gout, Hout, err
    ):
        """Add the field of one coaxial group at many points to the outputs (see
        :func:`_make_kernel`)."""
        want_B = (flags & WANT_B) != 0
        want_G = (flags & WANT_G) != 0
        want_H = (flags & WANT_H) != 0
        inv_L = params[0]
        fB = factor * params[1]
        fG = factor * params[2]
        fH = factor * params[3]
        far2 = params[4]
        d_far = params[5]
        kappa = params[6]
        tol2 = params[7]
        nx, ny, nz = axis[0], axis[1], axis[2]
        for j in range(err.shape[0]):
            err[j] = -1
        if digest == -1:  # never true: ties the cache entry to the sources (_source_digest)
            return -1
        nw = wind.shape[0]
        for k in range(pts.shape[0]):
            dx = pts[k, 0] - center[0]
            dy = pts[k, 1] - center[1]
            dz = pts[k, 2] - center[2]
            far = dx * dx + dy * dy + dz * dz > far2
            if far:
                # -- far zone: multipole series in coordinates scaled by 2^-e -----------------
                big = max(abs(dx), abs(dy), abs(dz))
                if not big < math.inf:
                    if err[ERR_OVERFLOW] < 0:
                        err[ERR_OVERFLOW] = k
                    continue
                e = math.frexp(big)[1]
                dx = math.ldexp(dx, -e)
                dy = math.ldexp(dy, -e)
                dz = math.ldexp(dz, -e)
            else:
                e = 0
                dx *= inv_L
                dy *= inv_L
                dz *= inv_L
            zl = dx * nx + dy * ny + dz * nz
            rx = dx - zl * nx
            ry = dy - zl * ny
            rz = dz - zl * nz
            u = rx * rx + ry * ry + rz * rz
            if far:
                r = math.sqrt(u + zl * zl)
                ir = 1.0 / r
                ir2 = ir * ir
                ir4 = ir2 * ir2
                ir6 = ir4 * ir2
                SBz, SQ, Sb1, Sq1, Sc1, Sd1 = multipole_point(
                    beta, n0, kappa, math.ldexp(d_far * ir, -e), zl * ir
                )
                Q = SQ * ir4
                Bz = SBz * ir2 * ir
                b1 = Sb1 * ir4 * ir
                q1 = Sq1 * ir6
                c1 = Sc1 * ir6
                d1 = Sd1 * ir6 * ir
            else:
                # -- near zone: sum over the filaments, in units of L -------------------------
                rho = math.sqrt(u)
                for j in range(nw):
                    if (
                        err[ERR_WINDING + j] < 0
                        and abs(zl - wind[j, 0]) < wind[j, 2]
                        and abs(rho - wind[j, 1]) < wind[j, 3]
                    ):
                        err[ERR_WINDING + j] = k
                ok, Q, Bz, b1, q1, c1, d1 = _near(fil, u, rho, zl, tol2, want_B, want_G, want_H)
                if not ok:
                    err[ERR_ON_WIRE] = k
                    return 1
            # q2 = (dq1/drho)/rho (Laplace); below u = 1e-200, q2 r r r is 1e-200 of q1 r: 0
            q2 = -(4.0 * q1 + c1) / u if want_H and u > 1e-200 else 0.0
            v = _global(rx, ry, rz, nx, ny, nz, u, Q, Bz, b1, q1, q2, c1, d1, want_G, want_H)
            # scale to SI: near, by factor / L^(1, 2, 3); far, by factor 2^(-3e, -4e, -5e) with
            # ldexp (one rounding, correct into the subnormal range)
            if far:
                sB, sG, sH = factor, factor, factor
                eB, eG, eH = -3 * e, -4 * e, -5 * e
            else:
                sB, sG, sH = fB, fG, fH
                eB = eG = eH = 0
            if not _store_point(
                Bout, Gout, Hout, k, v, sB, sG, sH, eB, eG, eH, far, want_B, want_G, want_H
            ):
                if err[ERR_NOT_FINITE] < 0:
                    err[ERR_NOT_FINITE] = k
        for j in range(err.shape[0]):
            if err[j] >= 0:
                return 1
        return 0

    return coaxial_field


#: The compiled pass (see :func:`_make_kernel` for its parameters).
coaxial_field = _make_kernel(_source_digest())
