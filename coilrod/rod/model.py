"""Which rod model a solve needs: the clamp frame, and whether field, magnetization and clamp
keep the rod in its plane (planar model) or not (spatial model)."""

from __future__ import annotations

import numpy as np

from coils.field import Field

__all__ = [
    "MODELS",
    "as_rotation",
    "clamp_frame",
    "choose_model",
    "planar_reasons",
    "reach_disc",
    "reach_fields",
    "plane_leak",
    "leaves_plane",
    "mirror_symmetric",
    "clamp_azimuth",
    "resolve_clamp_and_model",
]

MODELS = ("auto", "planar", "spatial")
#: Out-of-plane field (|B_z|, and L |dB_z/dx|, L |dB_z/dy|) on the plane of the rod, relative
#: to the largest |B| there, below which a field counts as planar: its effect on the rod is
#: below 1e-12 L, far under the solvers' accuracy.
PLANAR_FIELD_TOL = 1e-12
#: Orthonormality tolerance of a clamp rotation matrix (max-norm of R^T R - I).
ROTATION_TOL = 1e-9
#: :func:`planar_reasons`' reasons about the magnetization and the clamp rotation (the others
#: are the field's).
MAGNETIZATION_REASON = "the magnetization has an out-of-plane elevation"
CLAMP_REASON = "the clamp rotation turns the rod out of the x-y plane"


def as_rotation(value, name: str = "clamp_rotation") -> np.ndarray:
    """A rotation matrix (3, 3) from a (3, 3) array or a scipy ``Rotation`` (ValueError naming
    ``name`` unless finite, orthonormal to 1e-9 and of determinant +1).  The result is
    re-orthonormalised to machine precision (polar decomposition)."""
    if hasattr(value, "as_matrix") and callable(value.as_matrix):
        arr = np.asarray(value.as_matrix(), dtype=float)
        if arr.shape != (3, 3):
            raise ValueError(f"{name} must be a single rotation; got a stack of shape {arr.shape}")
    else:
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"{name} must be a 3x3 rotation matrix or a scipy Rotation; got {value!r}"
            ) from None
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must have shape (3, 3); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    err = float(np.max(np.abs(arr.T @ arr - np.eye(3))))
    if err > ROTATION_TOL:
        raise ValueError(
            f"{name} must be orthonormal (R^T R = I to {ROTATION_TOL:g}); its columns deviate by "
            f"{err:.3g}"
        )
    if np.linalg.det(arr) < 0:
        raise ValueError(f"{name} must be a proper rotation (determinant +1); it is a reflection")
    U, _, Vt = np.linalg.svd(arr)
    return U @ Vt


def clamp_frame(clamp_angle: float, clamp_rotation) -> np.ndarray:
    """The clamp frame (3, 3) (columns tangent, normal, binormal): ``clamp_rotation`` if given,
    else the rotation by ``clamp_angle`` (rad) about z.  Both given: ValueError unless the angle
    is 0."""
    if clamp_rotation is not None:
        if clamp_angle != 0.0:
            raise ValueError(
                "give the clamp orientation either as clamp_angle or as clamp_rotation, not both "
                f"(clamp_angle = {clamp_angle!r})"
            )
        return as_rotation(clamp_rotation, "clamp_rotation")
    from .so3 import about_z

    return about_z(clamp_angle)


def _in_plane_rotation(R0: np.ndarray) -> bool:
    """True if the frame keeps the binormal on +z (a rotation about z)."""
    r = np.asarray(R0, float).tolist()  # (plain floats: five comparisons, no numpy calls)
    return (
        abs(r[2][2] - 1.0) <= 1e-14
        and abs(r[2][0]) <= 1e-14
        and abs(r[2][1]) <= 1e-14
        and abs(r[0][2]) <= 1e-14
        and abs(r[1][2]) <= 1e-14
    )


def reach_disc(clamp: np.ndarray, length: float, radii: int = 17, angles: int = 48) -> np.ndarray:
    """Points (radii * angles, 3) m on the disc of radius ``length`` around ``clamp`` in the
    plane z = clamp_z: where a planar rod clamped there can reach."""
    r = np.linspace(0.0, length, radii)
    a = np.linspace(0.0, 2 * np.pi, angles, endpoint=False)
    pts = np.zeros((r.size * a.size, 3))
    pts[:, 0] = clamp[0] + np.outer(r, np.cos(a)).ravel()
    pts[:, 1] = clamp[1] + np.outer(r, np.sin(a)).ravel()
    pts[:, 2] = clamp[2]
    return pts


def reach_fields(evaluate, clamp: np.ndarray, length: float, radii: int = 17, angles: int = 48):
    """``evaluate(points)`` -> (B, G) on the :func:`reach_disc` of the rod.

    Where the whole disc cannot be evaluated (a coil winding inside it, a gridded field whose
    box does not cover it), the field is taken at every point of the disc where it can be
    (ring by ring, then point by point): never at the clamp alone.  ValueError when no point
    but the clamp can be evaluated."""
    pts = reach_disc(clamp, length, radii, angles)
    try:
        return evaluate(pts)
    except ValueError:
        pass
    parts = []
    beyond = 0  # points evaluated off the clamp
    for i, ring in enumerate(np.split(pts, radii)):
        try:
            parts.append(evaluate(ring))
            beyond += len(ring) if i else 0
            continue
        except ValueError:
            pass
        for p in ring:
            try:
                parts.append(evaluate(p[None]))
                beyond += 1 if i else 0
            except ValueError:
                continue
    if beyond == 0:
        raise ValueError(
            "the field cannot be evaluated on the plane around the clamp (the disc of radius "
            f"{length:g} m the rod can reach): cannot tell whether it keeps the rod in its "
            "plane -- give model='spatial' or a field defined there"
        )
    B = np.concatenate([p[0] for p in parts])
    G = np.concatenate([p[1] for p in parts])
    return B, G


def plane_leak(B, G, length: float, scale: float | None = None):
    """How far fields leave the plane: largest |B_z| (T), largest ``length`` |dB_z/dx|,
    ``length`` |dB_z/dy| (T), and the field's size (T; default the largest |B| entry) of
    fields B (n, 3, ...) and gradients G (n, 3, 3, ...) (trailing axes: per parameter or
    channel)."""
    B, G = np.asarray(B), np.asarray(G)
    bz = float(np.max(np.abs(B[:, 2])))
    gz = float(np.max(np.abs(G[:, 2, :2]))) * length
    if scale is None:
        scale = float(np.max(np.abs(B)))
    return bz, gz, max(scale, 1e-300)


def leaves_plane(B, G, length: float, scale: float | None = None) -> bool:
    """True if the fields B, G (see :func:`plane_leak`) have B_z or dB_z/dx, dB_z/dy above
    :data:`PLANAR_FIELD_TOL` of their size."""
    bz, gz, size = plane_leak(B, G, length, scale)
    return bz > PLANAR_FIELD_TOL * size or gz > PLANAR_FIELD_TOL * size


def mirror_symmetric(field: Field, z0: float) -> bool:
    """True if ``field``'s own data prove ``B_z = 0`` on the whole plane z = ``z0`` (m) (then
    ``dB_z/dx = dB_z/dy = 0`` there too: in-plane derivatives of zero); False if they do not
    (the field may still be planar: :func:`_field_reasons` then samples it).

    Sums and scaled fields are symmetric when every part is.  Coaxial coils
    (:class:`coils.coaxial.CoaxialCoils`: coils, pairs) are when their axis lies in the plane
    (``axis_z = 0``) and their centre on it: the reflection through the plane maps every loop
    onto itself with its current reversed, so ``B(x') = P B(x)`` (``P`` the reflection,
    ``x' = P x``) and on the plane ``B_z = -B_z``.  A linear field is when ``dB_z/dx`` and
    ``dB_z/dy`` are zero and ``B_z`` vanishes at one point of the plane.  Exact comparisons:
    any doubt leaves the decision to the sampled check."""
    from coils.coaxial import CoaxialCoils
    from coils.field import FieldSum, ScaledField
    from coils.ideal import LinearField, UniformField

    if isinstance(field, FieldSum):
        return all(mirror_symmetric(p, z0) for p in field.parts)
    if isinstance(field, ScaledField):
        return mirror_symmetric(field.field, z0)
    if isinstance(field, CoaxialCoils):
        return bool(field.axis[2] == 0.0 and field.center[2] == z0)
    if type(field) in (LinearField, UniformField):
        G = field.G
        return bool(
            G[2, 0] == 0.0
            and G[2, 1] == 0.0
            and field.B0[2] + G[2, 2] * (z0 - field.origin[2]) == 0.0
        )
    return False


def _field_reasons(field: Field, clamp: np.ndarray, length: float) -> list[str]:
    """Why ``field`` would push a rod clamped at ``clamp`` out of the plane z = clamp_z (empty
    if it does not): B_z or dB_z/dx, dB_z/dy nonzero on the disc of radius ``length`` the rod
    can reach.  Uniform fields are checked exactly, fields whose geometry proves the plane a
    mirror plane (:func:`mirror_symmetric`) are planar without evaluation, others are sampled
    on a polar grid of the disc (17 radii x 48 angles)."""
    uniform = bool(getattr(field, "uniform", False))
    if uniform:
        B = np.asarray(field.B(clamp)[0], float)
        if B[2] != 0.0 and abs(B[2]) > PLANAR_FIELD_TOL * np.linalg.norm(B):
            return [f"the field has an out-of-plane component B_z = {B[2]:.3g} T"]
        return []
    if mirror_symmetric(field, float(clamp[2])):
        return []
    B, G = reach_fields(field.B_and_gradient, clamp, length)
    bz, gz, scale = plane_leak(B, G, length, float(np.max(np.linalg.norm(B, axis=1))))
    reasons = []
    if bz > PLANAR_FIELD_TOL * scale:
        reasons.append(f"the field has an out-of-plane component |B_z| up to {bz:.3g} T")
    if gz > PLANAR_FIELD_TOL * scale:
        reasons.append(
            f"dB_z/dx, dB_z/dy up to {gz / length:.3g} T/m on the plane (an out-of-plane force)"
        )
    return reasons


def planar_reasons(rod, field: Field, clamp: np.ndarray, R0: np.ndarray) -> list[str]:
    """What keeps the rod from staying in the plane z = clamp_z (empty: the planar model is
    exact)."""
    reasons = []
    mag = rod.magnetization
    if not getattr(mag, "is_planar", True):
        reasons.append(MAGNETIZATION_REASON)
    if not _in_plane_rotation(R0):
        reasons.append(CLAMP_REASON)
    reasons += _field_reasons(field, np.asarray(clamp, float), rod.length)
    return reasons


def choose_model(model: str, rod, field: Field, clamp: np.ndarray, R0: np.ndarray) -> str:
    """ "planar" or "spatial" for the requested ``model`` ("auto", "planar", "spatial").

    "auto" is planar exactly when :func:`planar_reasons` finds nothing; "planar" with a reason
    raises ValueError (the planar model would drop out-of-plane loads)."""
    if not isinstance(model, str) or model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}; got {model!r}")
    if model == "spatial":
        return "spatial"
    reasons = planar_reasons(rod, field, clamp, R0)
    if model == "planar" and reasons:
        raise ValueError(
            "model='planar' would drop out-of-plane loads: "
            + "; ".join(reasons)
            + " -- use model='auto' or 'spatial'"
        )
    return "spatial" if reasons else "planar"


def clamp_azimuth(R0: np.ndarray) -> float:
    """Angle (rad) of the clamp tangent about z, ``atan2(t_y, t_x)``, in (-pi, pi]."""
    return float(np.arctan2(R0[1, 0], R0[0, 0]))


def resolve_clamp_and_model(model: str, rod, field: Field, clamp, clamp_angle, clamp_rotation):
    """(the model to run, the clamp frame (3, 3), the planar clamp angle): the frame of
    ``clamp_angle`` or ``clamp_rotation`` (:func:`clamp_frame`), the model of
    :func:`choose_model`, and for a planar run of a rotated clamp its angle about z."""
    R0 = clamp_frame(clamp_angle, clamp_rotation)
    chosen = choose_model(model, rod, field, clamp, R0)
    if chosen == "planar" and clamp_rotation is not None:
        clamp_angle = clamp_azimuth(R0)
    return chosen, R0, clamp_angle
