"""The ground truth of a simulated campaign: ``truth.json`` and the true corners, and reading them back.

A campaign written by the virtual test-bed (:mod:`stiffmap.campaign.simulated`,
:mod:`stiffmap.campaign.simulated_sensor`) keeps beside its spec and raw files
what the simulation knew (``docs/simulation.md``)::

    truth.json               # format TRUTH_FORMAT: true K per position, every image's poses,
                             # the true camera and the calibrated one, ...
    truth_corners.json.gz    # every image's (and calibration view's) true board poses and corner
                             # pixels (vision)
    .stiffmap-simulation     # marker written first (lets --force clean up an interrupted run)

:func:`load_truth` reads it back as a :class:`SimTruth`.
"""

from __future__ import annotations

import gzip
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..io import leaves_directory, read_json

__all__ = [
    "TRUTH_NAME",
    "CORNERS_NAME",
    "TRUTH_FORMAT",
    "MARKER_NAME",
    "SimTruth",
    "CalibrationSummary",
    "load_truth",
    "compact_json",
]

TRUTH_NAME = "truth.json"
CORNERS_NAME = "truth_corners.json.gz"
TRUTH_FORMAT = "stiffmap-sim-truth/1"
#: Written first: marks a directory as the simulator's even if a run was interrupted.
MARKER_NAME = ".stiffmap-simulation"


def compact_json(obj: Any, indent: int = 0, depth: int = 2) -> str:
    """JSON with dicts broken over lines down to ``depth`` and everything below on one line."""
    if depth <= 0 or not isinstance(obj, (dict, list)) or not obj:
        return json.dumps(obj, allow_nan=False, separators=(", ", ": "))
    pad = "  " * (indent + 1)
    if isinstance(obj, dict):
        items = [f"{pad}{json.dumps(k)}: {compact_json(v, indent + 1, depth - 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + "  " * indent + "}"
    items = [f"{pad}{compact_json(v, indent + 1, depth - 1)}" for v in obj]
    return "[\n" + ",\n".join(items) + "\n" + "  " * indent + "]"


_CAMERA_PARAMS = ("fx", "fy", "cx", "cy")


@dataclass(frozen=True)
class CalibrationSummary:
    """Where a simulated campaign's camera.json comes from (truth.json's ``calibration``).

    Attributes
    ----------
    calibrated : bool
        True: calibrated from the rendered calibration views; False: the true camera.
    note : str
        Why the true camera was given ("" when calibrated).
    n_views, n_used : int
        Calibration views rendered, and used by the calibration (0 with the true camera).
    rms_px : float
        Reprojection RMS of the calibration, px (NaN with the true camera).
    relative_error : dict
        ``fx``, ``fy``, ``cx``, ``cy``: (calibrated - true) / true (empty with the true camera).
    error_px : dict
        The same as differences (calibrated - true), px.
    """

    calibrated: bool
    note: str
    n_views: int
    n_used: int
    rms_px: float
    relative_error: dict[str, float]
    error_px: dict[str, float]

    @property
    def worst_relative_error(self) -> float:
        """Largest |relative error| of fx, fy, cx, cy."""
        return max((abs(float(v)) for v in self.relative_error.values()), default=0.0)

    def errors_text(self) -> str:
        """``fx +0.0012 % (+0.045 px), fy ...``: the calibrated camera against the true one."""
        return ", ".join(
            f"{k} {100 * self.relative_error[k]:+.4f} % ({self.error_px[k]:+.3f} px)" for k in _CAMERA_PARAMS
        )

    def describe(self) -> str:
        """One line: how camera.json was obtained and how far it is from the true camera."""
        if not self.calibrated:
            return f"camera.json is the true camera: {self.note}"
        return (
            f"camera.json calibrated from {self.n_used} of {self.n_views} rendered views "
            f"(RMS {self.rms_px:.4f} px); against the true camera: {self.errors_text()}"
        )

    def to_dict(self) -> dict:
        """A JSON object: ``camera_json`` ("calibrated" or "true camera"), note, views, numbers."""
        return {
            "camera_json": "calibrated" if self.calibrated else "true camera",
            "note": self.note,
            "views": self.n_views,
            "views_used": self.n_used,
            "rms_px": self.rms_px if self.calibrated else None,
            "relative_error": dict(self.relative_error) if self.calibrated else None,
            "error_px": dict(self.error_px) if self.calibrated else None,
        }

    @classmethod
    def from_truth(cls, data: dict, source: str = TRUTH_NAME) -> CalibrationSummary:
        """From a truth.json object (a truth without ``calibration``: the true camera)."""
        c = data.get("calibration")
        if c is None:
            return cls(False, "a simulation of stiffmap before calibration views", 0, 0, float("nan"), {}, {})
        try:
            if c.get("camera_json") != "calibrated":
                return cls(False, str(c.get("note", "")), 0, 0, float("nan"), {}, {})
            rel = {k: float(c["relative_error"][k]) for k in _CAMERA_PARAMS}
            err = {k: float(c["error_px"][k]) for k in _CAMERA_PARAMS}
            return cls(True, "", int(c["n_views"]), int(c["n_used"]), float(c["rms_px"]), rel, err)
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise InputError(
                f"key 'calibration': malformed ({type(e).__name__} {e})", source=source
            ) from None


@dataclass(frozen=True)
class SimTruth:
    """The ground truth of a simulated campaign (:func:`load_truth`).

    Attributes
    ----------
    root : Path
        The campaign directory.
    camera : CameraModel or None
        The true camera; None for a sensor campaign.
    cam2base : ndarray, shape (4, 4), or None
    positions : ndarray, shape (n, 3) (vision) or (n, 2) (sensor, planar), mm
    K : ndarray, shape (n, 3, 3) or (n, 2, 2), N/mm
        What a force-only identification should recover at each position.
    data : dict
        The whole truth.json.
    calibrated_camera : CameraModel or None
        The camera calibrated from the simulated calibration views, which the campaign's
        camera.json holds; None when the campaign was given the true camera (or for a
        sensor campaign). ``data["calibration"]`` says how it was obtained.
    """

    root: Path
    camera: CameraModel | None
    cam2base: np.ndarray | None
    positions: np.ndarray
    K: np.ndarray
    data: dict
    calibrated_camera: CameraModel | None = None

    @property
    def calibration(self) -> CalibrationSummary:
        """How the campaign's camera.json was obtained (calibrated, or the true camera)."""
        return CalibrationSummary.from_truth(self.data, str(self.root / TRUTH_NAME))

    def images(self) -> list[dict]:
        """Per image: file, indices, state, commanded and true tcp2base, photometry."""
        return self.data["images"]

    def corners(self) -> dict[str, dict]:
        """Per image file: ``{"fixed": {"board2cam", "corners_px"}, "mobile": {...}}`` (arrays).

        A rig campaign's entries also hold ``"cameras": {name: {"fixed": ..., "mobile": ...}}``
        (each camera's view; the top-level targets are the first camera's)."""
        name = self.data.get("corners_file", CORNERS_NAME)
        src = str(self.root / TRUTH_NAME)
        if not isinstance(name, str) or not name.strip():
            raise InputError(f"key 'corners_file': expected a file name, got {name!r}", source=src)
        how = leaves_directory(self.root, name)
        if how is not None:
            raise InputError(
                f"key 'corners_file': {name!r} {how}, outside the campaign directory", source=src
            )
        p = self.root / name
        try:
            raw = json.loads(gzip.decompress(p.read_bytes()).decode("utf-8"))
        except (OSError, ValueError, EOFError, RecursionError, gzip.BadGzipFile) as e:
            raise InputError(f"cannot read the true corners: {e}", source=str(p)) from None
        out = {}
        try:
            for im in raw["images"]:
                entry = _targets_truth({k: v for k, v in im.items() if k not in ("file", "cameras")})
                if "cameras" in im:  # a rig's images: each camera's own, the first's also at the top
                    entry["cameras"] = {cam: _targets_truth(t) for cam, t in im["cameras"].items()}
                out[im["file"]] = entry
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise InputError(f"malformed true corners: {type(e).__name__} {e}", source=str(p)) from None
        return out


def _targets_truth(targets: dict) -> dict[str, dict[str, np.ndarray]]:
    """``{target: {"board2cam", "corners_px"}}`` of one view with its values as arrays."""
    return {k: {kk: np.asarray(vv, dtype=np.float64) for kk, vv in v.items()} for k, v in targets.items()}


def load_truth(path: str | os.PathLike) -> SimTruth:
    """Read ``truth.json`` (a file, or a campaign directory holding one).

    Raises
    ------
    InputError
        Missing file, not JSON, not a stiffmap simulation truth, or a key missing.
    """
    p = Path(path)
    if p.is_dir():
        p = p / TRUTH_NAME
    src = str(p)
    if not p.is_file():
        raise InputError("no truth.json (not a simulated campaign?)", source=src)
    d = read_json(p, "truth.json")
    if not isinstance(d, dict) or d.get("format") != TRUTH_FORMAT:
        raise InputError(f"not a stiffmap simulation truth (expected format {TRUTH_FORMAT!r})", source=src)
    try:
        calibrated = None
        if d.get("kind") == "sensor":
            cam, cam2base = None, None
            m = 2
        else:
            cam = CameraModel.from_dict(d["camera"], source=f"{src}: camera")
            cam2base = _finite(d["cam2base"], (4, 4), "cam2base", src)
            if d.get("calibrated_camera") is not None:
                calibrated = CameraModel.from_dict(d["calibrated_camera"], source=f"{src}: calibrated_camera")
            m = 3
        entries = d["positions"]
        if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
            raise InputError("key 'positions': expected a non-empty list of objects", source=src)
        pos = np.stack(
            [_finite(e["position"], (m,), f"positions[{i}].position", src) for i, e in enumerate(entries)]
        )
        K = np.stack([_finite(e["K"], (m, m), f"positions[{i}].K", src) for i, e in enumerate(entries)])
    except KeyError as e:
        raise InputError(f"missing key {e.args[0]!r}", source=src) from None
    except (TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(f"malformed truth: {e}", source=src) from None
    return SimTruth(
        root=p.parent, camera=cam, cam2base=cam2base, positions=pos, K=K, data=d, calibrated_camera=calibrated
    )


def _finite(value: Any, shape: tuple[int, ...], key: str, src: str) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape``; InputError naming ``key`` otherwise."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        a = None
    if a is None or a.shape != shape or not np.all(np.isfinite(a)):
        raise InputError(f"key {key!r}: expected finite numbers of shape {shape}", source=src)
    return a
