"""Calibrated electromagnet models: the Multipole Electromagnet Model (MPEM).

Petruska, Edelmann & Nelson, "Model-based calibration for magnetic manipulation", IEEE Trans.
Magn. 53(7) (2017), model an electromagnetic navigation system (eMNS) with iron cores
by a few point dipoles per coil, fitted to field measurements.  The field is linear in the coil
currents, as for air coils:

    B(x; I) = B_offset(x) + sum_j I_j b_j(x),
    b_j(x) = sum_q c_q (3 r (d_q . r) - d_q |r|^2) / |r|^5,

with ``r = x - x_q`` from the source position ``x_q`` (m), ``d_q`` its unit direction and
``c_q`` its coefficient (T m^3 / A, the dipole moment already scaled by mu0/4pi); the
``Offset`` sources (T m^3) make the current-independent field.  :meth:`MPEM.from_yaml` reads
the YAML calibration files of ETH Zurich's Tesla / mag_manip tools (``Coil_List``, per coil a
``Source_List`` of sources with ``Source_Position``, ``Source_Direction``, ``B_Coeff`` and
``A_Coeff: ~``) and the calibrated workspace (``Workspace_Dimensions``); :mod:`coils.presets`
ships three of them (:func:`coils.presets.cardiomag`,
:func:`~coils.presets.navion`, :func:`~coils.presets.octomag`).

B, the gradient and the hessian are exact (:mod:`coils.dipoles`, one compiled pass).  A model
with a workspace refuses points well outside it (:data:`WORKSPACE_MARGIN`): a fit does not
extrapolate (1000 m away a point-dipole sum would ask for ~1e12 times the currents).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ._files import read_text
from ._immutable import sealed
from ._validate import _show, as_array, as_bool, as_limits, as_points, as_vector
from .currents import _fmt_mm
from .dipoles import dipole_sum
from .field import AccumulatedField

__all__ = ["MPEM"]

#: A point closer than this fraction of :attr:`MPEM.length_scale` to a source is "on" it.
ON_SOURCE = 1e-9
#: Largest accepted deviation of ``|Source_Direction|`` from 1 in a calibration file (the
#: public files round directions to 3 or more digits); the direction is used as written.
UNIT_TOL = 1e-3
#: How far beyond its calibrated workspace a model is evaluated, as a fraction of the
#: workspace's extent along each axis, on each side (0.5: a box twice the workspace's size):
#: a fit extrapolates smoothly somewhat beyond the measured region (grids and rods reach past
#: its faces), not to the coils and beyond; a point farther out is a ``ValueError``.
WORKSPACE_MARGIN = 0.5


class MPEM(AccumulatedField):
    """A calibrated multipole electromagnet model: point dipoles driven by coil currents.

    Parameters
    ----------
    coils : sequence of (positions, moments)
        One entry per coil (current channel, m of them): ``positions`` array-like (s, 3), the
        source positions in m, and ``moments`` array-like (s, 3), the dipole moments per ampere
        scaled by mu0/4pi (``B_Coeff * Source_Direction``), T m^3/A.
    offset : (positions, moments), optional
        Current-independent sources: positions (s, 3) in m, moments (s, 3) in T m^3.
    currents : array-like, shape (m,), optional
        Coil currents, A (default zero).
    max_current : float or array-like, shape (m,), optional
        Limit of ``|I_j|``, A (> 0; ``inf``: none; default none).
    names : sequence of str, shape (m,), optional
        Coil names (default ``Coil_0`` ...).
    center : array-like, shape (3,)
        Working point for :meth:`currents_for` and :meth:`ideal`, m (default the origin, the
        calibration frame's workspace centre).
    origin : str, optional
        Where the model comes from (a file name), quoted in error messages.
    workspace : array-like, shape (3, 2), optional
        The calibrated workspace, ``[[x_min, x_max], [y_min, y_max], [z_min, z_max]]`` in m
        (``Workspace_Dimensions`` of a calibration file).  Fields, gradients, unit fields and
        current solves at a point beyond it by more than :data:`WORKSPACE_MARGIN` of its
        extent along an axis raise ``ValueError`` (naming the point and the workspace).
        Default None: no workspace, the dipole sum is evaluated anywhere.

    Notes
    -----
    Immutable like every source: :meth:`with_currents`, :meth:`with_limits` and
    ``replace(...)`` return copies.  The model is a fit valid in the calibrated workspace
    (checked where it is given; ``replace(workspace=None)`` evaluates the dipole sum anywhere,
    at the caller's risk); it is a point-dipole sum, so it grows without bound near a source
    and a point on a source is refused (``ValueError`` naming the coil and source).

    Examples
    --------
    >>> from coils import MPEM
    >>> one = MPEM([([[0.0, 0.0, -0.1]], [[0.0, 0.0, 1e-7]])], max_current=10.0)
    >>> one.with_currents([2.0]).B([0.0, 0.0, 0.0])[0] * 1e3      # 2 c / r^3 * I, mT
    array([0. , 0. , 0.4])
    """

    _immutable = True

    def __init__(
        self,
        coils,
        offset=None,
        *,
        currents=None,
        max_current=None,
        names=None,
        center=(0.0, 0.0, 0.0),
        origin=None,
        workspace=None,
    ):
        if isinstance(coils, str | np.ndarray) or not isinstance(coils, Sequence) or not coils:
            raise ValueError(
                f"coils must be a non-empty sequence of (positions (s, 3), moments (s, 3)); "
                f"got {_show(coils)}"
            )
        m = len(coils)
        self.origin = None if origin is None else str(origin)
        self.names = (
            tuple(f"Coil_{j}" for j in range(m)) if names is None else self._as_names(names, m)
        )
        pos, mom, chan = [], [], []
        for j, entry in enumerate(coils):
            p, q = self._pair(entry, f"coils[{j}]")
            pos.append(p)
            mom.append(q)
            chan.append(np.full(len(p), j))
        if offset is not None:
            p, q = self._pair(offset, "offset")
            pos.append(p)
            mom.append(q)
            chan.append(np.full(len(p), -1))
        self.positions = sealed(np.vstack(pos))
        self.moments = sealed(np.vstack(mom))
        self.channel = sealed(np.concatenate(chan), dtype=np.int64)
        self.center = sealed(as_vector(center, "center"))
        self.workspace = None if workspace is None else sealed(self._as_workspace(workspace))
        self._currents = sealed(
            np.zeros(m) if currents is None else as_vector(currents, "currents", m)
        )
        self._max_current = sealed(
            np.full(m, np.inf) if max_current is None else as_limits(max_current, "max_current", m)
        )
        self._check_limits(self._currents)

    # -- construction helpers ------------------------------------------------------------------
    @staticmethod
    def _pair(entry, name: str):
        if not isinstance(entry, Sequence) or isinstance(entry, str) or len(entry) != 2:
            raise ValueError(
                f"{name} must be a pair (positions (s, 3), moments (s, 3)); got {_show(entry)}"
            )
        p = as_array(entry[0], f"{name} positions", ("s", 3))
        q = as_array(entry[1], f"{name} moments", (p.shape[0], 3))
        return p, q

    @staticmethod
    def _as_workspace(workspace, name: str = "workspace") -> np.ndarray:
        box = as_array(workspace, name, (3, 2))
        if not np.all(box[:, 0] < box[:, 1]):
            raise ValueError(
                f"{name} must be [[x_min, x_max], [y_min, y_max], [z_min, z_max]] m with each "
                f"min below its max; got {box.tolist()}"
            )
        return box

    def _check_workspace(self, pts: np.ndarray, name: str) -> None:
        """ValueError naming the first of ``pts`` (n, 3) m beyond the workspace by more than
        :data:`WORKSPACE_MARGIN` of its extent (no workspace: nothing checked)."""
        if self.workspace is None:
            return
        lo, hi = self.workspace.T
        pad = WORKSPACE_MARGIN * (hi - lo)
        lo, hi = lo - pad, hi + pad
        out = np.nonzero(~np.all((pts >= lo) & (pts <= hi), axis=1))[0]
        if out.size:
            k = int(out[0])
            # far out, and inside if read in mm: likely a length in mm
            far = np.any(np.abs(pts[k] - 0.5 * (lo + hi)) > 10 * (hi - lo))
            in_mm = far and np.all((1e-3 * pts[k] >= lo) & (1e-3 * pts[k] <= hi))
            where = f"{name}[{k}]" if name == "points" else name
            box = ", ".join(
                f"{axis} in [{1e3 * a:.4g}, {1e3 * b:.4g}] mm"
                for axis, (a, b) in zip("xyz", self.workspace, strict=True)
            )
            raise ValueError(
                f"{where} = {_fmt_mm(pts[k])} is outside the calibrated workspace"
                f"{self._where()}: {box} (accepted up to {WORKSPACE_MARGIN:.0%} of its extent "
                f"beyond each face); the fit does not hold there (use .replace(workspace=None) "
                f"to evaluate the dipole sum anywhere)"
                + ("; are the points in mm? coils takes metres" if in_mm else "")
            )

    @staticmethod
    def _as_names(names, m: int) -> tuple[str, ...]:
        if (
            isinstance(names, str)
            or not isinstance(names, Sequence)
            or len(names) != m
            or not all(isinstance(n, str) for n in names)
        ):
            raise ValueError(f"names must be a sequence of {m} strings; got {_show(names)}")
        twice = sorted({n for n in names if list(names).count(n) > 1})
        if twice:
            raise ValueError(f"names must be distinct (they name the channels); {twice} repeat")
        return tuple(names)

    def _where(self) -> str:
        return "" if self.origin is None else f" (model {self.origin})"

    def _source_label(self, q: int) -> str:
        j = int(self.channel[q])
        first = int(np.nonzero(self.channel == j)[0][0])
        owner = "Offset" if j < 0 else self.names[j]
        return f"source {q - first} of {owner}"

    def _how_to_change(self, name: str, value) -> str:
        hint = {"currents": "with_currents", "max_current": "with_limits"}.get(name)
        if hint is not None:
            return f"use .{hint}(...) for a changed copy"
        return super()._how_to_change(name, value)

    # -- channels --------------------------------------------------------------------------------
    @property
    def channels(self) -> tuple[str, ...]:
        """The current channels (the coils' names), length m."""
        return self.names

    @property
    def currents(self) -> np.ndarray:
        """Present coil currents, shape (m,), A (a copy)."""
        return self._currents.copy()

    @property
    def max_current(self) -> np.ndarray:
        """Current limit of each coil, shape (m,), A (``inf``: none; a copy)."""
        return self._max_current.copy()

    @property
    def length_scale(self) -> float:
        """Distance from :attr:`center` to the nearest source, m."""
        return float(np.linalg.norm(self.positions - self.center, axis=1).min())

    def _check_limits(self, currents: np.ndarray, name: str = "currents") -> None:
        over = np.nonzero(np.abs(currents) > self._max_current)[0]
        if over.size:
            j = int(over[0])
            raise ValueError(
                f"{name}[{j}] = {currents[j]:g} A exceeds max_current[{j}] = "
                f"{self._max_current[j]:g} A (channel {j}: {self.names[j]}){self._where()}"
            )

    def _coils_offset(self):
        m = len(self.names)
        coils = tuple(
            (self.positions[self.channel == j], self.moments[self.channel == j]) for j in range(m)
        )
        fixed = self.channel < 0
        offset = (self.positions[fixed], self.moments[fixed]) if fixed.any() else None
        return coils, offset

    def with_currents(self, currents) -> MPEM:
        """The same model with the coils driven by ``currents`` (shape (m,), A, within
        :attr:`max_current`; a ``ValueError`` names the channel over its limit)."""
        current = as_vector(currents, "currents", len(self.names))
        self._check_limits(current)
        return self.replace(currents=current)

    def with_limits(self, max_current) -> MPEM:
        """The same model with other current limits (A, scalar or (m,); the present currents
        must respect them)."""
        return self.replace(max_current=max_current)

    # -- evaluation -------------------------------------------------------------------------------
    def _run(self, pts, pos, mom, B, G, H) -> None:
        hit = dipole_sum(
            np.ascontiguousarray(pts), pos, mom, ON_SOURCE * self.length_scale, B, G, H
        )
        if hit >= 0:
            k, q = divmod(hit, pos.shape[0])
            # q indexes the sources passed; find it among all sources by position
            full = int(np.nonzero(np.all(self.positions == pos[q], axis=1))[0][0])
            raise ValueError(
                f"points[{k}] = {_fmt_mm(pts[k])} is on {self._source_label(full)}"
                f"{self._where()}: a point dipole's field is infinite there"
            )

    def _effective(self):
        scale = np.where(self.channel < 0, 1.0, self._currents[np.maximum(self.channel, 0)])
        return self.moments * scale[:, None]

    def _add_to(self, pts, B, G, H, factor):
        self._check_workspace(pts, "points")
        self._run(pts, self.positions, factor * self._effective(), B, G, H)

    def unit_fields(self, points, *, hessian: bool = False):
        """Field, gradient (and hessian) per ampere of every coil at ``points``.

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            Positions, m.
        hessian : bool
            Also return the second derivatives per ampere.

        Returns
        -------
        B : ndarray, shape (n, 3, m)
            T/A.
        G : ndarray, shape (n, 3, 3, m)
            ``dB_i/dx_l`` per ampere, T/(A m).
        H : ndarray, shape (n, 3, 3, 3, m)
            Only with ``hessian``, T/(A m^2).

        Notes
        -----
        The offset is not included: the field is ``fixed_field + B @ currents``.
        """
        pts = np.ascontiguousarray(as_points(points))
        hessian = as_bool(hessian, "hessian")
        self._check_workspace(pts, "points")
        n, m = pts.shape[0], len(self.names)
        B = np.zeros((m, n, 3))
        G = np.zeros((m, n, 3, 3))
        H = np.zeros((m, n, 3, 3, 3)) if hessian else None
        for j in range(m):
            sel = self.channel == j
            self._run(
                pts,
                np.ascontiguousarray(self.positions[sel]),
                np.ascontiguousarray(self.moments[sel]),
                B[j],
                G[j],
                H[j] if hessian else None,
            )
        out = (
            np.ascontiguousarray(np.moveaxis(B, 0, -1)),
            np.ascontiguousarray(np.moveaxis(G, 0, -1)),
        )
        if hessian:
            out += (np.ascontiguousarray(np.moveaxis(H, 0, -1)),)
        return out

    def fixed_field(self, points) -> tuple[np.ndarray, np.ndarray]:
        """B (n, 3) in T and gradient (n, 3, 3) in T/m of the offset sources at ``points``."""
        pts = np.ascontiguousarray(as_points(points))
        self._check_workspace(pts, "points")
        n = pts.shape[0]
        B, G = np.zeros((n, 3)), np.zeros((n, 3, 3))
        sel = self.channel < 0
        if sel.any():
            self._run(
                pts,
                np.ascontiguousarray(self.positions[sel]),
                np.ascontiguousarray(self.moments[sel]),
                B,
                G,
                None,
            )
        return B, G

    def currents_for(self, B=None, gradient=None, *, at=None, weights=None) -> np.ndarray:
        """The least-``sum w I^2`` currents that make a field and/or gradient at a point.

        Parameters
        ----------
        B : array-like, shape (3,), optional
            Target flux density, T.
        gradient : array-like, shape (3, 3), optional
            Target gradient ``dB_i/dx_j`` (symmetric, traceless), T/m.
        at : array-like, shape (3,), optional
            The point, m; default :attr:`center`.
        weights : array-like, shape (m,), optional
            Positive weights (default equal: the least ``sum I^2``).

        Returns
        -------
        ndarray, shape (m,)
            Currents, A, within :attr:`max_current`.

        Raises
        ------
        ValueError
            As :meth:`coils.CoilSystem.currents_for`: a target the coils cannot make (what
            they miss by), one beyond the limits (the fraction they allow), a bad argument.

        Examples
        --------
        >>> import numpy as np
        >>> from coils import presets
        >>> navion = presets.navion()
        >>> I = navion.currents_for(B=(0.0, 0.0, 20e-3))
        >>> np.round(1e3 * navion.with_currents(I).B([0.0, 0.0, 0.0])[0], 9) + 0.0
        array([ 0.,  0., 20.])
        """
        from .currents import currents_for_target

        point = self.center if at is None else as_vector(at, "at")
        self._check_workspace(point[None], "at" if at is not None else "center")
        words = {
            "who": f"the model{self._where()}",
            "channels": "coils",
            "channel": "coil",
            "limits": self._where(),
            "fixed": "the offset field",
            "currents": "least-norm",
        }
        default = np.ones(len(self.names))
        return currents_for_target(self, point, B, gradient, weights, default, self.names, words)

    def ideal(self, zero_tol: float = 1e-12):
        """The LinearField of B and gradient at :attr:`center` (:func:`coils.linearize`)."""
        from .ideal import linearize

        return linearize(self, self.center, zero_tol)

    def __repr__(self):
        return (
            f"MPEM({len(self.names)} coils, {self.positions.shape[0]} sources"
            f"{'' if self.origin is None else ', ' + repr(self.origin)})"
        )

    # -- files ------------------------------------------------------------------------------------
    @classmethod
    def from_yaml(cls, path, *, max_current=None, currents=None, center=(0.0, 0.0, 0.0)):
        """Read a calibration in the YAML format of the Tesla / mag_manip tools (ETH Zurich).

        Parameters
        ----------
        path : str or path-like
            The file: ``Coil_List`` (coil keys, in channel order), per coil a ``Source_List``
            and per source ``Source_Position`` (3 values, m), ``Source_Direction`` (3 values,
            unit to within 1e-3; used as written), ``B_Coeff`` (one value, T m^3/A) and
            ``A_Coeff: ~``; optionally ``Offset`` (sources of the current-independent field,
            ``B_Coeff`` in T m^3); optionally ``Workspace_Dimensions`` (3 pairs [min, max], m:
            the calibrated workspace, see the constructor's ``workspace``).  ``System_Name``
            is read and ignored.
        max_current, currents, center
            As for the constructor.

        Returns
        -------
        MPEM

        Raises
        ------
        ValueError
            Naming the file, the coil (or ``Offset``), the source and the key: a missing key,
            a wrong length, a non-unit direction, a non-finite number; and for models this
            class does not support, a non-null ``A_Coeff`` (higher-order sources) or
            saturation functions (the field would not be linear in the currents); a
            ``Workspace_Dimensions`` that is not 3 pairs [min, max] with min < max.
        """
        import yaml

        text = read_text(path, "MPEM file")
        path = Path(path)
        where = str(path)
        try:
            doc = yaml.load(text, Loader=_unique_key_loader())  # noqa: S506 - a SafeLoader
        except yaml.YAMLError as err:
            raise ValueError(f"{where} is not valid YAML: {err}") from None
        if not isinstance(doc, dict):
            raise ValueError(f"{where}: expected a mapping with Coil_List; got {_show(doc)}")
        for key in doc:
            if "satur" in str(key).lower():
                raise ValueError(
                    f"{where}: key {key!r}: saturation functions are not supported (the field "
                    f"would not be linear in the currents); use a model without them"
                )
        if "Coil_List" not in doc:
            raise ValueError(f"{where}: missing key 'Coil_List' (the list of coil keys)")
        coil_list = doc["Coil_List"]
        if not isinstance(coil_list, list) or not coil_list:
            raise ValueError(f"{where}: Coil_List must be a non-empty list of coil keys")
        twice = sorted({str(n) for n in coil_list if coil_list.count(n) > 1})
        if twice:
            raise ValueError(f"{where}: Coil_List names coil(s) {twice} more than once")
        coils = [cls._read_sources(doc, str(name), where, per_ampere=True) for name in coil_list]
        offset = (
            cls._read_sources(doc, "Offset", where, per_ampere=False) if "Offset" in doc else None
        )
        workspace = None
        if doc.get("Workspace_Dimensions") is not None:
            rows = doc["Workspace_Dimensions"]
            key = f"{where}: Workspace_Dimensions"
            if not isinstance(rows, list) or len(rows) != 3:
                raise ValueError(
                    f"{key} must be 3 pairs [min, max] (x, y, z), m; got {_show(rows)}"
                )
            rows = [_numbers(row, 2, f"{key}[{i}]") for i, row in enumerate(rows)]
            workspace = cls._as_workspace(rows, key)
        return cls(
            coils,
            offset,
            currents=currents,
            max_current=max_current,
            names=[str(n) for n in coil_list],
            center=center,
            origin=path.name,
            workspace=workspace,
        )

    @staticmethod
    def _read_sources(doc: dict, coil: str, where: str, per_ampere: bool):
        if coil not in doc:
            raise ValueError(f"{where}: coil {coil!r} is in Coil_List but has no entry")
        entry = doc[coil]
        if not isinstance(entry, dict) or "Source_List" not in entry:
            raise ValueError(f"{where}: {coil}: missing key 'Source_List'")
        for key in entry:
            if "satur" in str(key).lower():
                raise ValueError(
                    f"{where}: {coil}: key {key!r}: saturation functions are not supported "
                    f"(the field would not be linear in the currents)"
                )
        names = entry["Source_List"]
        if not isinstance(names, list) or not names:
            raise ValueError(f"{where}: {coil}: Source_List must be a non-empty list")
        twice = sorted({str(n) for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"{where}: {coil}: Source_List names source(s) {twice} more than once")
        pos, mom = [], []
        for src in names:
            at = f"{where}: {coil}: {src}"
            if src not in entry or not isinstance(entry[src], dict):
                raise ValueError(f"{at}: listed in Source_List but has no entry")
            s = entry[src]
            for key in ("Source_Position", "Source_Direction", "B_Coeff"):
                if key not in s:
                    raise ValueError(f"{at}: missing key {key!r}")
            if s.get("A_Coeff") is not None:
                raise ValueError(
                    f"{at}: A_Coeff is given ({_show(s['A_Coeff'])}): only dipole sources "
                    f"(A_Coeff: ~) are supported"
                )
            unknown = set(s) - {"Source_Position", "Source_Direction", "B_Coeff", "A_Coeff"}
            if unknown:
                raise ValueError(f"{at}: unknown key(s) {sorted(map(str, unknown))}")
            p = _numbers(s["Source_Position"], 3, f"{at}: Source_Position")
            d = _numbers(s["Source_Direction"], 3, f"{at}: Source_Direction")
            c = _numbers(s["B_Coeff"], 1, f"{at}: B_Coeff")[0]
            norm = float(np.linalg.norm(d))
            if abs(norm - 1.0) > UNIT_TOL:
                raise ValueError(
                    f"{at}: Source_Direction must be a unit vector; got |d| = {norm:.6g}"
                )
            pos.append(p)
            mom.append(c * d)
        return np.array(pos), np.array(mom)


def _construct_unique_mapping(loader, node, deep=False):
    """A YAML mapping; a key given twice is an error (plain YAML keeps the last silently)."""
    import yaml

    seen = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            continue  # the base constructor reports an unhashable key
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"the key {key!r} is given twice (lines {seen[key]} and "
                f"{key_node.start_mark.line + 1}); keep one",
            )
        seen[key] = key_node.start_mark.line + 1
    return yaml.SafeLoader.construct_mapping(loader, node, deep)


def _unique_key_loader():
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_constructor(
        yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
        lambda loader, node: _construct_unique_mapping(loader, node, deep=True),
    )
    return Loader


def _numbers(value, size: int, name: str) -> np.ndarray:
    if not isinstance(value, list):
        value = [value]
    if any(isinstance(v, bool | str) or v is None for v in value):
        # YAML reads true, 'text' and ~ fine; numpy would take true as 1 and '1e-3' as 1e-3
        raise ValueError(f"{name} must be {size} numbers; got {_show(value)}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {size} numbers; got {_show(value)}") from None
    if arr.shape != (size,):
        raise ValueError(f"{name} must have {size} entries; got {len(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    return arr
