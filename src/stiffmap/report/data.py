"""The report's data contract: what a campaign hands to :func:`stiffmap.report.write_report`.

Everything the report draws is in one :class:`ReportData`, built from frozen
dataclasses of numpy arrays. Units follow ``docs/conventions.md`` (N, mm,
N/mm) except where a field name says otherwise (``_um``, ``_px``, ``_n``).
Index conventions: ``n`` positions of a vision campaign, ``L`` load cases,
``R`` repeats, ``g`` points of a dense model map, ``m`` measured points of a
sensor campaign, ``N`` calibration corners.

A field holding NaN means "no value" and is always shown as such (a failed
position, a missing repeat); it never reaches a plot as a number. A position
whose ``status`` is ``"ok"`` must have a finite K.

JSON round trip: :meth:`ReportData.to_dict` gives plain JSON values (NaN as
``null``); :meth:`ReportData.from_dict` checks every key and raises
:class:`~stiffmap.errors.InputError` naming the key path (``measured.K``) and
what was expected.
"""

from __future__ import annotations

import base64
import binascii
import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from .. import __version__
from ..camera import CameraModel
from ..errors import InputError
from ..io import to_jsonable
from ..loads import MAX_FORCE_N
from ..stiffness import MAX_DISPLACEMENT_MM, MAX_POSITION_MM, MAX_STIFFNESS_N_PER_MM, stiffness_indices
from .records import dump_record, load_record, set_array, set_float, set_optional_array, set_strings

__all__ = [
    "SCHEMA",
    "KINDS",
    "CampaignInfo",
    "Parameter",
    "MeasuredStiffness",
    "LoadData",
    "ModelMap",
    "OrientationMap",
    "ModelStiffness",
    "TruthStiffness",
    "CalibrationData",
    "SensorMap",
    "SensorResults",
    "Failure",
    "SetupItem",
    "BoardImage",
    "Residuals",
    "ReportData",
]

#: Plausibility limits of the fields (a broken data.json is refused rather than drawn):
#: positions (mm), stiffness (N/mm) and det K ((N/mm)^3), forces (N), displacement norms
#: (mm), static errors (um), reprojection residuals (px).
POS = MAX_POSITION_MM
KLIM = MAX_STIFFNESS_N_PER_MM
DETLIM = MAX_STIFFNESS_N_PER_MM**3
FLIM = MAX_FORCE_N
DLIM = MAX_DISPLACEMENT_MM
UMLIM = 1e3 * MAX_DISPLACEMENT_MM
PXLIM = 1e6

#: Identifies the JSON dump of a :class:`ReportData`.
SCHEMA = "stiffmap.report/1"
#: Campaign kinds.
KINDS = ("vision", "sensor")
STATUSES = ("ok", "failed")


# --------------------------------------------------------------------------- helpers
def _indices(K: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """det, smallest principal stiffness and eigenvalues of the symmetric part (NaN where not ok)."""
    n = K.shape[0]
    det = np.full(n, np.nan)
    mp = np.full(n, np.nan)
    ev = np.full((n, 3), np.nan)
    for i in np.flatnonzero(ok):
        idx = stiffness_indices(K[i])
        det[i], mp[i], ev[i] = idx.det, idx.min_principal, idx.eigenvalues
    return det, mp, ev


# --------------------------------------------------------------------------- records
@dataclass(frozen=True)
class CampaignInfo:
    """What the campaign is (the report's header).

    Attributes
    ----------
    name : str
    kind : {"vision", "sensor"}
    version : str
        stiffmap version that produced the results.
    date : str
        ISO 8601 date (and time) of the run.
    campaign_dir : str
    notes : str
        Free text shown under the header (escaped, never interpreted as HTML).
    """

    name: str
    kind: str
    version: str = __version__
    date: str = ""
    campaign_dir: str = ""
    notes: str = ""

    def __post_init__(self) -> None:
        for f in fields(self):
            if not isinstance(getattr(self, f.name), str):
                raise ValueError(f"{f.name}: expected a string, got {getattr(self, f.name)!r}")
        if self.kind not in KINDS:
            raise ValueError(f"kind: expected one of {', '.join(KINDS)}, got {self.kind!r}")


@dataclass(frozen=True)
class Parameter:
    """A fitted (or fixed) model parameter.

    Attributes
    ----------
    name : str
    value : float
    std : float
        Standard error (1 sigma), NaN when the parameter was fixed.
    unit : str
    """

    name: str
    value: float
    std: float = math.nan
    unit: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name: expected a non-empty string, got {self.name!r}")
        if not isinstance(self.unit, str):
            raise ValueError(f"unit: expected a string, got {self.unit!r}")
        set_float(self, "value", self.value)
        set_float(self, "std", self.std, allow_nan=True)


@dataclass(frozen=True)
class Failure:
    """Something that failed (a file, a position, a point) and why."""

    item: str
    message: str

    def __post_init__(self) -> None:
        if not isinstance(self.item, str) or not isinstance(self.message, str):
            raise ValueError("item and message: expected strings")


@dataclass(frozen=True)
class MeasuredStiffness:
    """Measured stiffness per position of a vision campaign.

    Attributes
    ----------
    positions : ndarray, shape (n, 3), mm
        Positions of the point of interest in the base frame.
    status : tuple of str, (n,)
        ``"ok"`` or ``"failed"`` per position.
    messages : tuple of str, (n,)
        Why a position failed (empty when ok; required when failed).
    K : ndarray, shape (n, 3, 3), N/mm
        Identified stiffness, base frame; NaN for failed positions.
    K_std : ndarray, shape (n, 3, 3), N/mm
        Standard error of each entry (NaN when unknown).
    det : ndarray, shape (n,), (N/mm)^3
        det K (the reference study's map value).
    min_principal : ndarray, shape (n,), N/mm
        Smallest principal stiffness (eigenvalue of the symmetric part).
    eigenvalues : ndarray, shape (n, 3), N/mm
        Principal stiffnesses, ascending.
    flags : tuple of tuple of str, (n,)
        Physical and design flags per position (see ``identify.physical_flags``).

    Use :meth:`from_K` to compute ``det``, ``min_principal`` and ``eigenvalues``.
    """

    positions: np.ndarray
    status: tuple[str, ...]
    messages: tuple[str, ...]
    K: np.ndarray
    K_std: np.ndarray
    det: np.ndarray
    min_principal: np.ndarray
    eigenvalues: np.ndarray
    flags: tuple[tuple[str, ...], ...]

    def __post_init__(self) -> None:
        d: dict[str, int] = {}
        set_array(self, "positions", self.positions, ("n", 3), d, finite=True, limit=POS)
        n = d["n"]
        set_strings(self, "status", self.status, n)
        bad = [s for s in self.status if s not in STATUSES]
        if bad:
            raise ValueError(f"status: expected 'ok' or 'failed', got {bad[0]!r}")
        set_strings(self, "messages", self.messages, n, default=[""] * n)
        set_array(self, "K", self.K, ("n", 3, 3), d, limit=KLIM)
        set_array(self, "K_std", self.K_std, ("n", 3, 3), d, limit=KLIM)
        set_array(self, "det", self.det, ("n",), d, limit=DETLIM)
        set_array(self, "min_principal", self.min_principal, ("n",), d, limit=KLIM)
        set_array(self, "eigenvalues", self.eigenvalues, ("n", 3), d, limit=KLIM)
        fl = self.flags if self.flags is not None else [()] * n
        if len(fl) != n:
            raise ValueError(f"flags: expected {n} lists, got {len(fl)}")
        flags = []
        for i, f in enumerate(fl):
            if isinstance(f, str) or not all(isinstance(s, str) for s in f):
                raise ValueError(f"flags[{i}]: expected a list of strings, got {f!r}")
            flags.append(tuple(f))
        object.__setattr__(self, "flags", tuple(flags))
        ok = self.ok
        for i in np.flatnonzero(ok):
            if not np.all(np.isfinite(self.K[i])):
                raise ValueError(f"K[{i}]: position {i} has status 'ok' but K holds NaN")
            if not (np.isfinite(self.det[i]) and np.isfinite(self.min_principal[i])):
                raise ValueError(f"det/min_principal[{i}]: position {i} has status 'ok' but NaN indices")
        for i in np.flatnonzero(~ok):
            if not self.messages[i].strip():
                raise ValueError(f"messages[{i}]: position {i} failed; say why")

    @property
    def n(self) -> int:
        """Number of positions."""
        return int(self.positions.shape[0])

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of the positions with a stiffness, shape (n,)."""
        return np.array([s == "ok" for s in self.status], dtype=bool)

    @classmethod
    def from_K(
        cls,
        positions,
        K,
        K_std=None,
        *,
        status: Sequence[str] | None = None,
        messages: Sequence[str] | None = None,
        flags: Sequence[Sequence[str]] | None = None,
    ) -> MeasuredStiffness:
        """Build from stiffness matrices, computing det, eigenvalues and smallest principal.

        Parameters
        ----------
        positions : array_like, shape (n, 3), mm
        K : array_like, shape (n, 3, 3), N/mm
            NaN for failed positions.
        K_std : array_like, shape (n, 3, 3), N/mm, optional
            NaN when not given.
        status : sequence of str, optional
            Default: ``"failed"`` where K holds NaN, ``"ok"`` elsewhere.
        messages, flags : optional
            Default: empty (a position failed by NaN gets "no stiffness").
        """
        K = np.asarray(K, dtype=np.float64)
        if K.ndim != 3 or K.shape[1:] != (3, 3):
            raise ValueError(f"K: expected shape (n, 3, 3), got {K.shape}")
        n = K.shape[0]
        finite = np.all(np.isfinite(K), axis=(1, 2))
        if status is None:
            status = ["ok" if f else "failed" for f in finite]
        ok = np.array([s == "ok" for s in status], dtype=bool)
        if messages is None:
            messages = ["" if o else "no stiffness" for o in ok]
        K_std = np.full((n, 3, 3), np.nan) if K_std is None else K_std
        det, mp, ev = _indices(K, ok & finite)
        return cls(
            positions=positions,
            status=tuple(status),
            messages=tuple(messages),
            K=K,
            K_std=K_std,
            det=det,
            min_principal=mp,
            eigenvalues=ev,
            flags=tuple(tuple(f) for f in flags) if flags is not None else ((),) * n,
        )


@dataclass(frozen=True)
class LoadData:
    """Load cases and the displacement measured for each (the reference's Figs. 9-10).

    Attributes
    ----------
    labels : tuple of str, (L,)
        Load-case names, e.g. ``"0.5 kg +y"``.
    forces : ndarray, shape (L, 3), N
        Applied force of each load case, base frame.
    norms : ndarray, shape (n, L, R), mm
        Norm of the compliant displacement per position, load case and repeat;
        NaN where a repeat is missing.
    vectors : ndarray, shape (n, L, R, 3), mm, or None
        The compliant displacement itself (translation, base frame), NaN where missing;
        its norms are ``norms``. Drawn against the force (linearity, per load direction).
    residuals : ndarray, shape (n, L, R, 3), mm, or None
        What the identified K leaves of each displacement: d - C F (- b), with C = K^-1 and
        b the offset the fit estimated when every displacement of a position was measured
        against one (mean) reference (``identify_stiffness(offset=True)``); NaN where the
        displacement or K is missing.
    """

    labels: tuple[str, ...]
    forces: np.ndarray
    norms: np.ndarray
    vectors: np.ndarray | None = None
    residuals: np.ndarray | None = None

    def __post_init__(self) -> None:
        d: dict[str, int] = {}
        set_array(self, "forces", self.forces, ("L", 3), d, finite=True, limit=FLIM)
        set_strings(self, "labels", self.labels, d["L"])
        set_array(self, "norms", self.norms, ("n", "L", "R"), d, limit=DLIM)
        if np.any(self.norms < 0):
            raise ValueError("norms: a displacement norm is negative")
        set_optional_array(self, "vectors", self.vectors, ("n", "L", "R", 3), d, limit=DLIM)
        set_optional_array(self, "residuals", self.residuals, ("n", "L", "R", 3), d, limit=DLIM)
        if self.vectors is not None:
            nv = np.linalg.norm(self.vectors, axis=3)
            both = np.isfinite(nv) & np.isfinite(self.norms)
            if np.any(np.isfinite(nv) != np.isfinite(self.norms)) or not np.allclose(
                nv[both], self.norms[both], rtol=1e-9, atol=1e-12
            ):
                raise ValueError("vectors: their norms are not the norms given (or NaN elsewhere)")

    def summary(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mean and standard deviation (n - 1) over the repeats, and the count.

        Returns
        -------
        mean, std : ndarray, shape (n, L), mm
            NaN where no repeat (mean) or fewer than two repeats (std) exist.
        count : ndarray of int, shape (n, L)
        """
        x = self.norms
        cnt = np.sum(np.isfinite(x), axis=2)
        s = np.where(np.isfinite(x), x, 0.0).sum(axis=2)
        mean = np.full(cnt.shape, np.nan)
        np.divide(s, cnt, out=mean, where=cnt > 0)
        dev = np.where(np.isfinite(x), x - mean[..., None], 0.0)
        std = np.full(cnt.shape, np.nan)
        np.divide(np.sqrt((dev**2).sum(axis=2)), np.sqrt(np.maximum(cnt - 1, 1)), out=std, where=cnt > 1)
        return mean, std, cnt


@dataclass(frozen=True)
class ModelMap:
    """A model evaluated densely over the workspace (for instance on the measured planes).

    Attributes
    ----------
    points : ndarray, shape (g, 3), mm
        Base frame. Points sharing a z value form one plane panel.
    det : ndarray, shape (g,), (N/mm)^3
        NaN where the model cannot be evaluated (outside the workspace).
    min_principal : ndarray, shape (g,), N/mm
    """

    points: np.ndarray
    det: np.ndarray
    min_principal: np.ndarray

    def __post_init__(self) -> None:
        d: dict[str, int] = {}
        set_array(self, "points", self.points, ("g", 3), d, finite=True, limit=POS)
        set_array(self, "det", self.det, ("g",), d, limit=DETLIM)
        set_array(self, "min_principal", self.min_principal, ("g",), d, limit=KLIM)


#: Largest plausible rotational stiffness, N*mm/rad (a translational one's times (1 m)^2).
KRLIM = KLIM * 1e6


@dataclass(frozen=True)
class OrientationMap:
    """A platform that turns (a ``dim = 6`` robot): its model over orientations at one position,
    roll and pitch on a grid (yaw as the campaign's), measured beside it.

    Attributes
    ----------
    position : ndarray, shape (3,), mm
        Where the platform's tool point stays.
    yaw_deg : float
    roll_deg : ndarray, shape (a,), degrees
    pitch_deg : ndarray, shape (b,), degrees
    min_principal : ndarray, shape (b, a), N/mm
        The smallest principal stiffness of the K the campaign identifies (the loads' forces
        hung at ``loads.point_mm``), row j at pitch j; NaN where the model has none.
    min_principal_rot : ndarray, shape (b, a), N*mm/rad
        The smallest principal stiffness a pure moment sees (K_rot).
    measured_rpy_deg : ndarray, shape (k, 3), degrees
        The orientations measured at that position.
    measured_min_principal : ndarray, shape (k,), N/mm
        Their identified K's smallest principal stiffness (NaN: failed).
    """

    position: np.ndarray
    yaw_deg: float
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    min_principal: np.ndarray
    min_principal_rot: np.ndarray
    measured_rpy_deg: np.ndarray
    measured_min_principal: np.ndarray

    def __post_init__(self) -> None:
        d: dict[str, int] = {}
        set_array(self, "position", self.position, (3,), d, finite=True, limit=POS)
        set_float(self, "yaw_deg", self.yaw_deg)
        set_array(self, "roll_deg", self.roll_deg, ("a",), d, finite=True, limit=360.0)
        set_array(self, "pitch_deg", self.pitch_deg, ("b",), d, finite=True, limit=360.0)
        set_array(self, "min_principal", self.min_principal, ("b", "a"), d, limit=KLIM)
        set_array(self, "min_principal_rot", self.min_principal_rot, ("b", "a"), d, limit=KRLIM)
        set_array(self, "measured_rpy_deg", self.measured_rpy_deg, ("k", 3), d, finite=True, limit=360.0)
        set_array(self, "measured_min_principal", self.measured_min_principal, ("k",), d, limit=KLIM)


@dataclass(frozen=True)
class ModelStiffness:
    """A mechanism model fitted to (or compared with) the measurements.

    Attributes
    ----------
    name : str
    parameters : tuple of Parameter
        With standard errors for the fitted ones.
    K : ndarray, shape (n, 3, 3), N/mm
        Model stiffness at the measured positions (NaN where not evaluable).
    det : ndarray, shape (n,), (N/mm)^3
    min_principal : ndarray, shape (n,), N/mm
    map : ModelMap or None
        Dense model map over the workspace planes.
    orientations : OrientationMap or None
        A platform that turns: the model over orientations at one position.
    notes : tuple of str
        What the fit accounted for, in words (e.g. the extra noise it estimated).
    """

    name: str
    parameters: tuple[Parameter, ...]
    K: np.ndarray
    det: np.ndarray
    min_principal: np.ndarray
    map: ModelMap | None = None
    orientations: OrientationMap | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise ValueError(f"name: expected a string, got {self.name!r}")
        if not all(isinstance(p, Parameter) for p in self.parameters):
            raise ValueError("parameters: expected Parameter objects")
        object.__setattr__(self, "parameters", tuple(self.parameters))
        d: dict[str, int] = {}
        set_array(self, "K", self.K, ("n", 3, 3), d, limit=KLIM)
        set_array(self, "det", self.det, ("n",), d, limit=DETLIM)
        set_array(self, "min_principal", self.min_principal, ("n",), d, limit=KLIM)
        if self.map is not None and not isinstance(self.map, ModelMap):
            raise ValueError("map: expected a ModelMap")
        if self.orientations is not None and not isinstance(self.orientations, OrientationMap):
            raise ValueError("orientations: expected an OrientationMap")
        if isinstance(self.notes, str) or not all(isinstance(n, str) for n in self.notes):
            raise ValueError("notes: expected a sequence of strings")
        object.__setattr__(self, "notes", tuple(self.notes))

    @classmethod
    def from_K(
        cls,
        name: str,
        parameters: Sequence[Parameter],
        K,
        map: ModelMap | None = None,
        orientations: OrientationMap | None = None,
        notes: Sequence[str] = (),
    ):
        """Build from model stiffness matrices (det and smallest principal computed)."""
        K = np.asarray(K, dtype=np.float64)
        if K.ndim != 3 or K.shape[1:] != (3, 3):
            raise ValueError(f"K: expected shape (n, 3, 3), got {K.shape}")
        det, mp, _ = _indices(K, np.all(np.isfinite(K), axis=(1, 2)))
        return cls(name, tuple(parameters), K, det, mp, map, orientations, tuple(notes))


@dataclass(frozen=True)
class TruthStiffness:
    """Ground truth of a virtual test-bed campaign.

    Attributes
    ----------
    K : ndarray, shape (n, 3, 3), N/mm
        True stiffness at the measured positions.
    """

    K: np.ndarray

    def __post_init__(self) -> None:
        set_array(self, "K", self.K, ("n", 3, 3), {}, finite=True, limit=KLIM)


@dataclass(frozen=True)
class CalibrationData:
    """Camera calibration results.

    Attributes
    ----------
    camera : dict
        The ``camera.json`` object (``fx, fy, cx, cy, dist``, optionally ``std``,
        ``rms_px``, ``residual_std_px``, ``views`` with a per-view ``rms_px``).
    corner_residuals_px : ndarray, shape (N, 2), px, or None
        Reprojection residual (observed - projected) of every corner used.
    k_share : ndarray, shape (n, 3), or None
        Per measured position, the calibration's share (0..1) of the variance of k11, k22,
        k33 (NaN: unknown at that position); None when the campaign does not say.
    cameras : tuple of dict
        With several cameras (a rig): per camera, ``name``, ``camera`` (its ``camera.json``
        object), ``cam2rig`` (4x4, mm), and what it gave over the campaign's image sets:
        ``sets`` (image sets measured), ``seen`` (sets in which it saw a board), ``rms_px``
        (median reprojection RMS over those, px, or None), ``rms_px_p95`` and ``errors`` (a
        few of its error messages). Empty with one camera (``camera`` is then the one).
    """

    camera: dict
    corner_residuals_px: np.ndarray | None = None
    k_share: np.ndarray | None = None
    cameras: tuple[dict, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.camera, Mapping):
            raise ValueError(f"camera: expected an object, got {type(self.camera).__name__}")
        try:
            CameraModel.from_dict(dict(self.camera), source="camera")
        except InputError as e:
            raise ValueError(e.detail) from None
        object.__setattr__(self, "camera", dict(self.camera))
        _check_view_corners(self.camera.get("views") or [])
        set_optional_array(
            self, "corner_residuals_px", self.corner_residuals_px, ("N", 2), {}, finite=True, limit=PXLIM
        )
        set_optional_array(self, "k_share", self.k_share, ("n", 3), {}, limit=1.0)
        cams = tuple(self.cameras)
        for i, c in enumerate(cams):
            if not isinstance(c, Mapping) or not isinstance(c.get("name"), str):
                raise ValueError(f"cameras[{i}]: expected an object with a 'name'")
            try:
                CameraModel.from_dict(dict(c.get("camera") or {}), source=f"cameras[{i}]")
            except InputError as e:
                raise ValueError(e.detail) from None
        object.__setattr__(self, "cameras", tuple(dict(c) for c in cams))


def _check_view_corners(views: list) -> None:
    """The corners and residuals a ``camera.json`` view may keep: (k, 2) finite px, as many of each."""
    for i, v in enumerate(views):
        if not isinstance(v, Mapping) or ("corners_px" not in v and "residuals_px" not in v):
            continue
        shapes = []
        for key in ("corners_px", "residuals_px"):
            where = f"camera.views[{i}].{key}"
            try:
                a = np.array(v.get(key), dtype=np.float64)
            except (TypeError, ValueError, OverflowError):
                raise ValueError(f"{where}: expected a list of [x, y] pixel pairs") from None
            if a.ndim != 2 or a.shape[1] != 2 or not np.all(np.isfinite(a)) or np.any(np.abs(a) > PXLIM):
                raise ValueError(
                    f"{where}: expected a list of finite [x, y] pixel pairs, got shape {a.shape}"
                )
            shapes.append(a.shape)
        if shapes[0] != shapes[1]:
            raise ValueError(f"camera.views[{i}]: {shapes[0][0]} corners but {shapes[1][0]} residuals")


@dataclass(frozen=True)
class SensorMap:
    """A dense model map of the static error for one load direction.

    Attributes
    ----------
    direction : str
        Load (and measurement) direction, e.g. ``"x"`` or ``"y"``.
    points : ndarray, shape (g, 2), mm
        Tool positions in the mechanism's plane.
    error_um : ndarray, shape (g,), um
        Static error at the reference load; NaN where not reachable.
    """

    direction: str
    points: np.ndarray
    error_um: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.direction, str) or not self.direction:
            raise ValueError(f"direction: expected a non-empty string, got {self.direction!r}")
        d: dict[str, int] = {}
        set_array(self, "points", self.points, ("g", 2), d, finite=True, limit=POS)
        set_array(self, "error_um", self.error_um, ("g",), d, limit=UMLIM)


@dataclass(frozen=True)
class SensorResults:
    """Static-error results of a sensor campaign (the milling study's Figs. 11-14).

    One row per measured (point, direction) pair.

    Attributes
    ----------
    points : ndarray, shape (m, 2), mm
        Tool position of each measurement, in the mechanism's plane.
    direction : tuple of str, (m,)
        Load and measurement direction of each row (``"x"``, ``"y"``).
    error_um : ndarray, shape (m,), um
        Measured static error (displacement along ``direction``) at the reference
        load; NaN where the measurement failed.
    error_std_um : ndarray, shape (m,), um
        Its standard deviation (NaN when unknown).
    labels : tuple of str, (m,)
        Point names (e.g. the study's numbering "2", "5", ...); default "1".. "m".
    model_error_um : ndarray, shape (m,), um, or None
        Model static error at the same points and directions.
    middle_line : ndarray of bool, shape (m,), or None
        Rows on the workspace's vertical middle line, compared point by point
        (the study's Figs. 11-12). None: every measured row is compared.
    reference_load_n : float
        Load at which the static error is given, N (default 50 kgf = 490.5 N).
    model_name : str
    parameters : tuple of Parameter
        Fitted model parameters (e.g. ``kj`` in N/mm with its standard error).
    maps : tuple of SensorMap
        Dense model maps, one per direction.
    step_load_n : ndarray, shape (m, S), N, or None
        The load of each static plateau of each recording (NaN-padded to S steps).
    step_um : ndarray, shape (m, S), um, or None
        The displacement on each plateau (along ``direction``).
    fit_um_per_n, fit_intercept_um : ndarray, shape (m,), or None
        The load-displacement line fitted to each recording's plateaus (um/N, um), whose
        value at ``reference_load_n`` is its static error; NaN where it failed.
    """

    points: np.ndarray
    direction: tuple[str, ...]
    error_um: np.ndarray
    error_std_um: np.ndarray
    labels: tuple[str, ...] | None = None
    model_error_um: np.ndarray | None = None
    middle_line: np.ndarray | None = None
    reference_load_n: float = 490.5
    model_name: str = ""
    parameters: tuple[Parameter, ...] = ()
    maps: tuple[SensorMap, ...] = ()
    step_load_n: np.ndarray | None = None
    step_um: np.ndarray | None = None
    fit_um_per_n: np.ndarray | None = None
    fit_intercept_um: np.ndarray | None = None

    def __post_init__(self) -> None:
        d: dict[str, int] = {}
        set_array(self, "points", self.points, ("m", 2), d, finite=True, limit=POS)
        m = d["m"]
        set_strings(self, "direction", self.direction, m)
        if not all(self.direction):
            raise ValueError("direction: empty direction name")
        set_array(self, "error_um", self.error_um, ("m",), d, limit=UMLIM)
        set_array(self, "error_std_um", self.error_std_um, ("m",), d, limit=UMLIM)
        set_strings(self, "labels", self.labels, m, default=[str(i + 1) for i in range(m)])
        set_optional_array(self, "model_error_um", self.model_error_um, ("m",), d, limit=UMLIM)
        if self.middle_line is not None:
            ml = np.asarray(self.middle_line)
            if ml.shape != (m,) or ml.dtype != bool:
                raise ValueError(f"middle_line: expected {m} booleans, got {ml.dtype} {ml.shape}")
            ml = ml.copy()
            ml.setflags(write=False)
            object.__setattr__(self, "middle_line", ml)
        set_float(self, "reference_load_n", self.reference_load_n, positive=True)
        if not isinstance(self.model_name, str):
            raise ValueError("model_name: expected a string")
        if not all(isinstance(p, Parameter) for p in self.parameters):
            raise ValueError("parameters: expected Parameter objects")
        object.__setattr__(self, "parameters", tuple(self.parameters))
        if not all(isinstance(s, SensorMap) for s in self.maps):
            raise ValueError("maps: expected SensorMap objects")
        object.__setattr__(self, "maps", tuple(self.maps))
        set_optional_array(self, "step_load_n", self.step_load_n, ("m", "S"), d, limit=FLIM)
        set_optional_array(self, "step_um", self.step_um, ("m", "S"), d, limit=UMLIM)
        set_optional_array(self, "fit_um_per_n", self.fit_um_per_n, ("m",), d, limit=UMLIM)
        set_optional_array(self, "fit_intercept_um", self.fit_intercept_um, ("m",), d, limit=UMLIM)
        if (self.step_load_n is None) != (self.step_um is None):
            raise ValueError("step_load_n and step_um: give both or neither")

    @property
    def m(self) -> int:
        return int(self.points.shape[0])

    @property
    def directions(self) -> tuple[str, ...]:
        """The distinct directions, in order of first appearance."""
        return tuple(dict.fromkeys(self.direction))


@dataclass(frozen=True)
class SetupItem:
    """One line of the set-up summary: what, and its value as text (``"load cases"``, ``"9: ..."``)."""

    what: str
    value: str

    def __post_init__(self) -> None:
        if not isinstance(self.what, str) or not self.what or not isinstance(self.value, str):
            raise ValueError("what and value: expected strings (what not empty)")


#: Largest embedded image (base64 characters): a downsampled grey photograph is far below it.
MAX_IMAGE_B64 = 8_000_000
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class BoardImage:
    """One image of the campaign with its boards drawn where their measured poses put them.

    Attributes
    ----------
    name : str
        The image file (as the campaign names it).
    png_base64 : str
        The image, grey, reduced by ``scale``: a PNG file, base64-encoded.
    image_size : ndarray, shape (2,), px
        [w, h] of the image file.
    scale : float
        Image pixels per pixel of the PNG (>= 1).
    corners_px : ndarray, shape (N, 2), px
        The boards' inner corners projected from their measured poses (board2cam) through
        the camera, in the image file's pixels (x right, y down).
    corner_board : tuple of str, (N,)
        Which board each corner belongs to (``"mobile 15x14"``, ``"fixed 9x6"``).
    """

    name: str
    png_base64: str
    image_size: np.ndarray
    scale: float
    corners_px: np.ndarray
    corner_board: tuple[str, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not isinstance(self.png_base64, str):
            raise ValueError("name and png_base64: expected strings")
        if len(self.png_base64) > MAX_IMAGE_B64:
            raise ValueError(f"png_base64: {len(self.png_base64)} characters, more than an image needs")
        try:
            png = base64.b64decode(self.png_base64, validate=True)
        except (binascii.Error, ValueError):
            raise ValueError("png_base64: not base64") from None
        if png[:8] != _PNG_SIGNATURE or len(png) < 33 or png[12:16] != b"IHDR":
            raise ValueError("png_base64: not a PNG image")
        w, h = struct.unpack(">II", png[16:24])
        d: dict[str, int] = {}
        set_array(self, "image_size", self.image_size, (2,), d, finite=True, limit=1e5)
        set_float(self, "scale", self.scale, positive=True)
        W, H = self.image_size
        if abs(w * self.scale - W) > self.scale or abs(h * self.scale - H) > self.scale:
            raise ValueError(f"png_base64: a {w}x{h} PNG at scale {self.scale:g} is not a {W:g}x{H:g} image")
        set_array(self, "corners_px", self.corners_px, ("N", 2), d, finite=True, limit=PXLIM)
        set_strings(self, "corner_board", self.corner_board, d["N"])

    @property
    def png(self) -> bytes:
        """The PNG file."""
        return base64.b64decode(self.png_base64)


@dataclass(frozen=True)
class Residuals:
    """Measured minus modelled, at the measured positions (NaN where either is missing).

    Attributes
    ----------
    K : ndarray, shape (n, 3, 3), N/mm
    det : ndarray, shape (n,), (N/mm)^3
    min_principal : ndarray, shape (n,), N/mm
    """

    K: np.ndarray
    det: np.ndarray
    min_principal: np.ndarray


# --------------------------------------------------------------------------- report data
@dataclass(frozen=True)
class ReportData:
    """Everything a report shows.

    Attributes
    ----------
    campaign : CampaignInfo
    measured : MeasuredStiffness or None
        Required for a vision campaign.
    loads : LoadData or None
        Load cases and displacement norms per position (same n as ``measured``).
    model : ModelStiffness or None
    truth : TruthStiffness or None
        Virtual test-bed ground truth.
    calibration : CalibrationData or None
    sensor : SensorResults or None
        Required for a sensor campaign.
    failures : tuple of Failure
        Every item that failed, listed in the report.
    setup : tuple of SetupItem
        What the campaign did: loads, images or recordings, boards, camera, failures.
    board_image : BoardImage or None
        One image with the detected boards drawn on it.
    """

    campaign: CampaignInfo
    measured: MeasuredStiffness | None = None
    loads: LoadData | None = None
    model: ModelStiffness | None = None
    truth: TruthStiffness | None = None
    calibration: CalibrationData | None = None
    sensor: SensorResults | None = None
    failures: tuple[Failure, ...] = ()
    setup: tuple[SetupItem, ...] = ()
    board_image: BoardImage | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.campaign, CampaignInfo):
            raise ValueError("campaign: expected a CampaignInfo")
        if self.campaign.kind == "vision" and self.measured is None:
            raise ValueError("measured: a vision campaign needs the measured stiffness")
        if self.campaign.kind == "sensor" and self.sensor is None:
            raise ValueError("sensor: a sensor campaign needs the sensor results")
        n = self.measured.n if self.measured is not None else None
        for name, part, attr in (
            ("loads", self.loads, "norms"),
            ("model", self.model, "K"),
            ("truth", self.truth, "K"),
        ):
            if part is None:
                continue
            if n is None:
                raise ValueError(f"{name}: given without the measured stiffness")
            k = getattr(part, attr).shape[0]
            if k != n:
                raise ValueError(f"{name}.{attr}: {k} positions, but measured has {n}")
        if not all(isinstance(f, Failure) for f in self.failures):
            raise ValueError("failures: expected Failure objects")
        object.__setattr__(self, "failures", tuple(self.failures))
        if not all(isinstance(x, SetupItem) for x in self.setup):
            raise ValueError("setup: expected SetupItem objects")
        object.__setattr__(self, "setup", tuple(self.setup))
        if self.board_image is not None and not isinstance(self.board_image, BoardImage):
            raise ValueError("board_image: expected a BoardImage")

    # ------------------------------------------------------------------ derived
    @property
    def residuals(self) -> Residuals | None:
        """Measured minus modelled (None without a model)."""
        if self.model is None or self.measured is None:
            return None
        ok = self.measured.ok
        dK = np.where(ok[:, None, None], self.measured.K - self.model.K, np.nan)
        return Residuals(
            dK,
            np.where(ok, self.measured.det - self.model.det, np.nan),
            np.where(ok, self.measured.min_principal - self.model.min_principal, np.nan),
        )

    @property
    def truth_error(self) -> np.ndarray | None:
        """Relative Frobenius error |K - K_true|_F / |K_true|_F per position, shape (n,).

        NaN for failed positions; None without truth.
        """
        if self.truth is None or self.measured is None:
            return None
        num = np.linalg.norm(self.measured.K - self.truth.K, axis=(1, 2))
        den = np.linalg.norm(self.truth.K, axis=(1, 2))
        return np.where(self.measured.ok, num / den, np.nan)

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (NaN as ``null``), with ``"schema": SCHEMA``."""
        return {"schema": SCHEMA, **to_jsonable(dump_record(self))}

    @classmethod
    def from_dict(cls, data: Any, source: str | None = None) -> ReportData:
        """Rebuild from :meth:`to_dict` output (``null`` read back as NaN).

        Raises
        ------
        InputError
            Naming ``source``, the key path and what was expected.
        """
        if not isinstance(data, Mapping):
            raise InputError(f"expected a JSON object, got {type(data).__name__}", source=source)
        schema = data.get("schema")
        if schema != SCHEMA:
            raise InputError(f"key 'schema': expected {SCHEMA!r}, got {schema!r}", source=source)
        body = {k: v for k, v in data.items() if k != "schema"}
        return _load(cls, body, "", source)


# --------------------------------------------------------------------------- (de)serialisation
#: Nested record types of each field that holds records.
_NESTED: dict[tuple[type, str], type] = {
    (ReportData, "campaign"): CampaignInfo,
    (ReportData, "measured"): MeasuredStiffness,
    (ReportData, "loads"): LoadData,
    (ReportData, "model"): ModelStiffness,
    (ReportData, "truth"): TruthStiffness,
    (ReportData, "calibration"): CalibrationData,
    (ReportData, "sensor"): SensorResults,
    (ModelStiffness, "map"): ModelMap,
    (ModelStiffness, "orientations"): OrientationMap,
    (ReportData, "board_image"): BoardImage,
}
_NESTED_LISTS: dict[tuple[type, str], type] = {
    (ReportData, "failures"): Failure,
    (ModelStiffness, "parameters"): Parameter,
    (SensorResults, "parameters"): Parameter,
    (SensorResults, "maps"): SensorMap,
    (ReportData, "setup"): SetupItem,
}


#: Fields whose JSON values are arrays of numbers (``null`` means NaN).
_ARRAY_FIELDS = {
    "positions",
    "K",
    "K_std",
    "det",
    "min_principal",
    "eigenvalues",
    "forces",
    "norms",
    "points",
    "corner_residuals_px",
    "k_share",
    "error_um",
    "error_std_um",
    "model_error_um",
    "vectors",
    "residuals",
    "step_load_n",
    "step_um",
    "fit_um_per_n",
    "fit_intercept_um",
    "image_size",
    "corners_px",
    "position",
    "roll_deg",
    "pitch_deg",
    "min_principal_rot",
    "measured_rpy_deg",
    "measured_min_principal",
}


def _load(cls: type, data: Any, path: str, source: str | None):
    return load_record(
        cls, data, path, source, nested=_NESTED, nested_lists=_NESTED_LISTS, array_fields=_ARRAY_FIELDS
    )
