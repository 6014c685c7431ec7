"""The JSON objects of vision results: what ``stiffmap pose``, ``displacement`` and ``validate``
print with ``--json`` (docs/vision.md), one home for their keys.

Arrays stay NumPy arrays here; :func:`stiffmap.io.dumps_json` writes them as lists (NaN as
null).
"""

from __future__ import annotations

from collections.abc import Mapping

from .displacement import Displacement, ImageDisplacements
from .fuse import FusedPose
from .sequence import ImageMeasurement
from .validate import StageValidation

__all__ = ["pose_record", "displacement_records", "validation_record"]


def _pose_keys(p) -> dict:
    """JSON fields of a pose (a camera's or a rig's) beyond the pose and cov."""
    d = {"rms_px": p.rms_px, "n_corners": p.n_corners, "method": p.method}
    # The calibration's share of cov (None: the camera.json gives no uncertainty).
    d["cov_calibration"] = p.cov_calibration
    d["t_std_calibration_mm"] = None if p.cov_calibration is None else p.t_std_calibration_mm
    if p.photometric is not None:
        f = p.photometric
        d["photometric"] = {
            "rms_dn": f.rms_dn,
            "noise_rms_dn": f.noise_rms_dn,
            "n_pixels": f.n_pixels,
            "blur_px": f.blur_px,
            "outlier_fraction": f.outlier_fraction,
        }
    if p.fallback:
        d["fallback"] = p.fallback
    return d


def _camera_pose(p) -> dict | None:
    if p is None:
        return None
    d = {"board2cam": p.board2cam, "rms_px": p.rms_px, "n_corners": p.n_corners, "method": p.method}
    if p.fallback:
        d["fallback"] = p.fallback
    return d


def cameras_record(m: ImageMeasurement) -> list[dict]:
    """Per camera of a rig: its image, error, and the poses it measured (camera frame)."""
    return [
        {
            "name": v.camera,
            "image": v.image,
            "error": v.error,
            "mobile": _camera_pose(v.mobile),
            "fixed": _camera_pose(v.fixed),
        }
        for v in m.views
    ]


def _consistency(p) -> dict | None:
    if not isinstance(p, FusedPose):
        return None
    return {"cameras": list(p.cameras), "chi2": p.chi2, "dof": p.dof, "warning": p.consistency_warning}


def pose_record(m: ImageMeasurement, with_cameras: bool = False) -> dict:
    """The JSON object of one image (set): its pose, or its error; with a rig, each camera's.

    Keys: ``image``, then ``board2cam`` (4x4, mm; with a rig ``board2rig``, and ``frame`` is
    ``"rig"``), ``cov`` (6x6: t in mm, r in rad), ``rms_px``, ``n_corners``,
    ``method``, ``cov_calibration``, ``t_std_calibration_mm``, ``photometric`` and
    ``fallback`` when they apply; or ``error``. With a rig also ``consistency`` and
    ``cameras`` (what each camera saw).
    """
    cams = {"cameras": cameras_record(m)} if with_cameras else {}
    if not m.ok:
        return {"image": m.image, "error": m.error, **cams}
    pose = "board2rig" if with_cameras else "board2cam"
    row = {"image": m.image, pose: m.mobile.board2frame, "cov": m.mobile.cov, **_pose_keys(m.mobile)}
    if with_cameras:
        row["frame"] = "rig"
        row["consistency"] = _consistency(m.mobile)
    return {**row, **cams}


def _calibration_keys(d: Displacement) -> dict:
    """The calibration's part of a displacement's propagated 1 sigma (None: unknown).

    ``calibration_share`` is the share of each component's variance (dx..rz) from the camera's
    calibration, an error common to every displacement measured with the camera.
    """
    if d.cov_calibration is None:
        return {"d_std_calibration": None, "r_std_calibration": None, "calibration_share": None}
    return {
        "d_std_calibration": d.d_sigma_calibration,
        "r_std_calibration": d.r_sigma_calibration,
        "calibration_share": d.calibration_share,
    }


def displacement_records(
    res: ImageDisplacements, frame_names: Mapping[str, str] | None = None, with_cameras: bool = False
) -> list[dict]:
    """The JSON list: one object per image (its displacement or its error), then the mean.

    With a rig (``with_cameras``), each image set's object also holds ``cameras`` (what each
    camera saw) and the references come first, marked ``"reference": true``. ``frame_names``
    renames frames (a rig's ``cam`` frame is ``rig``).
    """
    frame_names = frame_names or {}
    rows = []
    if with_cameras:
        for m in res.references:
            rows.append({"image": m.image, "reference": True, "error": m.error, "cameras": cameras_record(m)})
    for m, dsp in zip(res.images, res.displacements, strict=True):
        cams = {"cameras": cameras_record(m)} if with_cameras else {}
        if dsp is None:
            rows.append({"image": m.image, "error": m.error, **cams})
            continue
        rows.append(
            {
                "image": m.image,
                "frame": frame_names.get(dsp.frame, dsp.frame),
                "d": dsp.d,
                "r": dsp.r,
                "d_std": dsp.d_sigma,
                "r_std": dsp.r_sigma,
                **_calibration_keys(dsp),
                **cams,
            }
        )
    s = res.summary
    if s is not None:
        rows.append(
            {
                "image": None,
                "summary": "mean over images",
                "frame": frame_names.get(s.frame, s.frame),
                "n": s.n,
                "d": s.d,
                "r": s.r,
                "d_std": s.d_std,
                "r_std": s.r_std,
                "d_sigma": s.d_sigma,
                "r_sigma": s.r_sigma,
                **_calibration_keys(s),
            }
        )
    return rows


def validation_record(res: StageValidation) -> dict:
    """The JSON object of a stage validation: each step, the axis, the RMS error, failures."""
    return {
        "steps": [
            {
                "nominal_mm": s.nominal_mm,
                "mean_mm": s.mean_mm,
                "std_mm": s.std_mm,
                "n": s.n,
                "error_mm": s.error_mm,
                "along_mean_mm": s.along_mean_mm,
                "along_std_mm": s.along_std_mm,
            }
            for s in res.steps
        ],
        "axis": res.axis,
        "n_reference": res.n_reference,
        "rms_error_mm": res.rms_error_mm,
        "failed": [{"image": a, "error": e} for a, e in res.failed],
    }
