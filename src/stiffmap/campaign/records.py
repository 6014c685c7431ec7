"""What the results database holds, typed: one frozen dataclass per table of ``stiffmap.db``.

:class:`~stiffmap.campaign.store.Store` returns these, decoded once: the JSON text of a
column is an array (float64, read-only, a JSON ``null`` entry as NaN) or the object it
encodes (a flag list, a parameter dict), as each class's ``JSON`` says; NULL is None. The
attributes are the tables' columns (``docs/campaigns.md``, "The results database").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

__all__ = [
    "MeasurementRecord",
    "DisplacementRecord",
    "RepeatStatRecord",
    "StiffnessRecord",
    "ModelFitRecord",
    "ModelStiffnessRecord",
    "SensorResultRecord",
    "ARRAY",
    "OBJECT",
]

#: How a JSON column decodes: an array of floats, or the JSON object as it is.
ARRAY = "array"
OBJECT = "object"

Array = np.ndarray | None


@dataclass(frozen=True)
class MeasurementRecord:
    """One image (or image set) of a position: its board poses (``measurements``).

    ``mobile2cam``, ``fixed2cam``, ``mobile2base`` (4, 4) mm; ``mobile_cov``, ``fixed_cov``,
    ``base_cov`` (6, 6); ``mobile_cal_jac``, ``fixed_cal_jac`` (6, n) against the camera
    parameters; ``per_camera`` a list of dicts (a rig's views), or None.
    """

    image: str
    position: int
    board_set: str
    sha256: str | None
    params_hash: str
    version: str
    status: str
    error: str | None
    mobile2cam: Array
    mobile_cov: Array
    fixed2cam: Array
    fixed_cov: Array
    mobile2base: Array
    base_cov: Array
    rms_px: float | None
    n_corners: int | None
    tracked: int | None
    seconds: float | None
    mobile_cal_jac: Array
    fixed_cal_jac: Array
    per_camera: Any

    JSON: ClassVar[dict[str, str]] = {
        "mobile2cam": ARRAY,
        "mobile_cov": ARRAY,
        "fixed2cam": ARRAY,
        "fixed_cov": ARRAY,
        "mobile2base": ARRAY,
        "base_cov": ARRAY,
        "mobile_cal_jac": ARRAY,
        "fixed_cal_jac": ARRAY,
        "per_camera": OBJECT,
    }


@dataclass(frozen=True)
class DisplacementRecord:
    """One load case and repeat of a position: its compliant displacement (``displacements``).

    ``d`` (6,) mm and rad (dx..dz, rx..rz) in ``frame``; ``cov`` and ``cov_calibration``
    (6, 6), the latter the calibration's share.
    """

    position: int
    load: int
    repeat: int
    unloaded: str
    loaded: str
    frame: str | None
    d: Array
    cov: Array
    status: str
    error: str | None
    params_hash: str
    version: str
    cov_calibration: Array

    JSON: ClassVar[dict[str, str]] = {"d": ARRAY, "cov": ARRAY, "cov_calibration": ARRAY}


@dataclass(frozen=True)
class RepeatStatRecord:
    """ISO 5725 statistics of one quantity over a load case's repeats (``repeat_stats``)."""

    position: int
    load: int
    quantity: str
    mean: float | None
    std: float | None
    n: int

    JSON: ClassVar[dict[str, str]] = {}


@dataclass(frozen=True)
class StiffnessRecord:
    """K identified at one position (``stiffness``): N/mm, base frame.

    ``K``, ``K_std`` (3, 3); ``K_cov``, ``K_cov_calibration`` (9, 9) over K's entries
    row-major (the latter the calibration's share); ``eigenvalues`` (3,); ``residual_rms``
    per displacement component; ``flags`` a list of texts; ``precision`` the repeat
    statistics' summary (a dict).
    """

    position: int
    x: float
    y: float
    z: float
    status: str
    error: str | None
    method: str | None
    K: Array
    K_std: Array
    K_cov: Array
    det: float | None
    eigenvalues: Array
    min_principal: float | None
    K_condition: float | None
    design_condition: float | None
    rank: int | None
    dof: int | None
    n_obs: int | None
    residual_rms: Array
    flags: Any
    precision: Any
    inputs_hash: str
    params_hash: str
    version: str
    K_cov_calibration: Array

    JSON: ClassVar[dict[str, str]] = {
        "K": ARRAY,
        "K_std": ARRAY,
        "K_cov": ARRAY,
        "eigenvalues": ARRAY,
        "residual_rms": ARRAY,
        "flags": OBJECT,
        "precision": OBJECT,
        "K_cov_calibration": ARRAY,
    }

    @property
    def point(self) -> np.ndarray:
        """(x, y, z), mm."""
        return np.array([self.x, self.y, self.z])


@dataclass(frozen=True)
class ModelFitRecord:
    """A model fit (``model_fit``): ``name`` ``stiffness`` (to K) or ``static_error``.

    ``params`` and ``std`` dicts (name -> value, in the parameter's unit); ``cov`` their
    covariance; ``residuals`` per pose; ``robot`` the fingerprint of the robot fitted
    (:mod:`~stiffmap.campaign.fingerprint`; None in a database of schema 3 and before);
    ``info`` what the fit accounted for, in words (e.g. the extra noise it estimated; a list of
    str, None before schema 5).
    """

    name: str
    model: str
    status: str
    error: str | None
    params: Any
    std: Any
    cov: Array
    residuals: Array
    condition: float | None
    dof: int | None
    inputs_hash: str
    version: str
    robot: Any = None
    info: Any = None

    JSON: ClassVar[dict[str, str]] = {
        "params": OBJECT,
        "std": OBJECT,
        "cov": ARRAY,
        "residuals": ARRAY,
        "robot": OBJECT,
        "info": OBJECT,
    }


@dataclass(frozen=True)
class ModelStiffnessRecord:
    """The model's K at one position (``model_stiffness``), N/mm; ``valid`` 0 with a ``reason``."""

    position: int
    model: str
    valid: int
    reason: str | None
    K: Array
    det: float | None
    min_principal: float | None
    inputs_hash: str

    JSON: ClassVar[dict[str, str]] = {"K": ARRAY}


@dataclass(frozen=True)
class SensorResultRecord:
    """One recording's analysis (``sensor_results``): ``point`` a list (mm), ``result`` a dict."""

    recording: str
    point: Any
    direction: str | None
    sha256: str | None
    params_hash: str
    version: str
    status: str
    error: str | None
    result: Any

    JSON: ClassVar[dict[str, str]] = {"point": OBJECT, "result": OBJECT}
