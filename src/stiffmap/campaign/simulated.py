"""Write a simulated vision campaign directory: the virtual test-bed's images as a normal campaign.

Layout (``docs/simulation.md``)::

    OUT_DIR/
      campaign.toml            # stiffmap's campaign spec (positions and loads as explicit lists)
      camera.json              # the camera calibrated from calibration/ (or the true one)
      calibration/view01.png, ...   # views of the calibration board (SimConfig.calibration_views)
      images/p01/l01_r01_unloaded.png, images/p01/l01_r01_loaded.png, ...
      truth.json               # the ground truth (written last: its presence marks a finished run)
      truth_corners.json.gz    # every image's true board poses and corner pixels
      .stiffmap-simulation     # marker written first (lets --force clean up an interrupted run)

The images and their truth come from the test-bed (:mod:`stiffmap.sim.testbed`,
:mod:`stiffmap.sim.render_pool`); this module lays them out in the campaign
format. As a lab does before a campaign, the camera is calibrated first: the
test-bed renders views of a calibration board at the poses a careful user takes
(:mod:`stiffmap.sim.calibration_views`), :func:`stiffmap.vision.files.calibrate_files`
(what ``stiffmap calibrate`` runs: detection, then Zhang's method, model ``k3``)
calibrates the camera from them, and that camera, with its covariance, is the
campaign's camera.json; truth.json keeps the true camera beside it. With
``calibration_views = 0``, or without images, camera.json is the true camera.

Every file is written atomically. A directory that is not empty is refused unless
``force``, and ``force`` only overwrites a previous simulation (a directory whose
``truth.json`` or marker the simulator wrote): raw images of a real campaign are
never deleted.
"""

from __future__ import annotations

import gzip
import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..camera import plausibility_problems, save_camera
from ..errors import InputError
from ..geometry import invert_transform, rotvec_from_matrix
from ..io import atomic_write_bytes, atomic_write_text, to_jsonable
from ..parallel import Backend, connected
from ..rig import Rig, save_rig
from ..sim.calibration_views import (
    CALIBRATION_BOARD,
    CALIBRATION_DIR,
    CALIBRATION_MARGIN_MM,
    RIG_POSE_KEY,
    CalibrationView,
    calibration_view_file,
    plan_calibration_views,
    render_rig_view,
    rig_calibration_views,
)
from ..sim.render import encode_image
from ..sim.render_pool import render_calibration_images, render_campaign_images
from ..sim.robot import LINKS_NAME, URDF_NAME
from ..sim.testbed import CampaignPlan, SimConfig, plan_campaign, seeded_generator
from ..vision.calibrate import CalibrationResult
from ..vision.files import calibrate_files, calibrate_rig_files
from ..vision.rig_calibration import RigCalibrationResult
from .spec import CampaignSpec
from .spec_writer import dump_spec
from .store import remove_database
from .truth import (
    CORNERS_NAME,
    MARKER_NAME,
    TRUTH_FORMAT,
    TRUTH_NAME,
    CalibrationSummary,
    compact_json,
)

__all__ = [
    "SimSummary",
    "calibrate_from_views",
    "write_campaign",
    "campaign_spec_dict",
    "check_output_dir",
    "prepare_output_dir",
]

RIG_NAME = "rig.json"
_OWN_FILES = ("campaign.toml", "camera.json", RIG_NAME, TRUTH_NAME, CORNERS_NAME, URDF_NAME, LINKS_NAME)
#: The distortion model of the calibration (``stiffmap calibrate``'s default).
CALIBRATION_MODEL = "k3"


def calibration_model(camera) -> str:
    """The distortion model a simulated camera is calibrated with: ``fisheye`` for a fisheye lens,
    else :data:`CALIBRATION_MODEL` (as a user who knows the lens calls ``stiffmap calibrate``)."""
    return "fisheye" if camera.model == "fisheye" else CALIBRATION_MODEL


@dataclass(frozen=True)
class SimSummary:
    """What :func:`write_campaign` wrote.

    Attributes
    ----------
    out_dir : Path
    n_positions, n_loads, repeats, n_images : int
    images_rendered : bool
        False when only the truth was written (``render_images=False``).
    bytes_written : int
        Size of the images (calibration views included), bytes.
    seconds : float
        Wall time.
    principal_range : (float, float)
        Smallest and largest principal stiffness over the positions, N/mm.
    files : tuple of str
        The campaign's own files (relative paths), images excluded.
    calibration : CalibrationSummary
        How camera.json was obtained (calibrated from views, or the true camera).
    calibration_seconds : float
        Wall time of rendering the calibration views and calibrating (0 without).
    setup : tuple of (str, str)
        What was simulated, in words, for the summary: ("positions", ...), ("loads", ...) of a
        robot of one's own (empty for a test-bed robot: its documented set-up).
    notes : tuple of str
        What the user should know (default positions left out).
    warnings : tuple of str
        What the user should look at (a load file's forces too small to measure).
    """

    out_dir: Path
    n_positions: int
    n_loads: int
    repeats: int
    n_images: int
    images_rendered: bool
    bytes_written: int
    seconds: float
    principal_range: tuple[float, float]
    files: tuple[str, ...]
    calibration: CalibrationSummary
    calibration_seconds: float = 0.0
    setup: tuple[tuple[str, str], ...] = ()
    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()


# ------------------------------------------------------------------ directory


def check_output_dir(out_dir: str | os.PathLike, force: bool = False) -> bool:
    """Check that a campaign may be written to ``out_dir`` (nothing is changed).

    Returns
    -------
    bool
        True when a previous simulation is there and will be overwritten (``force``).

    Raises
    ------
    InputError
        Not a directory; not empty without ``force``; not a previous simulation with ``force``.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a directory", source=str(out))
    if not out.exists() or not any(out.iterdir()):
        return False
    if not force:
        raise InputError(
            "the output directory is not empty; choose a new one, or give --force to overwrite "
            "a previous simulation",
            source=str(out),
        )
    ours = False
    for name in (MARKER_NAME, TRUTH_NAME):
        if (out / name).is_file():
            try:
                ours = (
                    ours or json.loads((out / name).read_text(encoding="utf-8")).get("format") == TRUTH_FORMAT
                )
            except (OSError, ValueError, AttributeError):
                pass
    if not ours:
        raise InputError(
            f"--force only overwrites a previous simulation (a directory with the {TRUTH_NAME} that "
            "'stiffmap simulate' writes); this one is not, so nothing was deleted",
            source=str(out),
        )
    return True


def prepare_output_dir(out: Path, force: bool) -> None:
    """Create ``out``, or empty a previous simulation there (``force``); then write the marker.

    Raises
    ------
    InputError
        As :func:`check_output_dir`.
    """
    if not check_output_dir(out, force):
        out.mkdir(parents=True, exist_ok=True)
    else:
        # truth.json goes first: an interrupted clean-up never leaves a "finished" mark; the
        # marker stays, so a second --force can finish the job.
        for name in (TRUTH_NAME, *_OWN_FILES):
            p = out / name
            if p.is_file():
                p.unlink()
        for sub in ("images", CALIBRATION_DIR, "recordings"):  # a vision or a sensor simulation
            if (out / sub).is_dir():
                shutil.rmtree(out / sub)
        # Results of 'stiffmap run' on the previous simulation: they describe images that are
        # gone, and a run on the new ones must not mix with them.
        remove_database(out)
        for sub in ("exports", "report"):
            if (out / sub).is_dir():
                shutil.rmtree(out / sub)
    atomic_write_text(out / MARKER_NAME, json.dumps({"format": TRUTH_FORMAT}) + "\n")


# ------------------------------------------------------------------ spec/truth


def _positions_table(config: SimConfig) -> dict[str, Any]:
    """campaign.toml's ``[positions]``: the points, or a serial robot's joint configurations at
    them when it was given configurations (its inverse kinematics may not find those again)."""
    q_deg = getattr(config.robot.field, "positions_q_deg", None)
    q = None if q_deg is None else q_deg(config.positions)
    if q is not None:
        return {"q_deg": q}
    if config.orientations is not None:  # a platform held turned: x, y, z mm, roll, pitch, yaw deg
        deg = np.round(np.degrees(config.orientations), 9) + 0.0
        return {"poses": [[float(v) for v in (*p, *a)] for p, a in zip(config.positions, deg, strict=True)]}
    return {"list": [[float(v) for v in p] for p in config.positions]}


def campaign_spec_dict(config: SimConfig, plan: CampaignPlan) -> dict[str, Any]:
    """The ``campaign.toml`` content (a dict for :class:`stiffmap.campaign.spec.CampaignSpec`)."""
    sc = config.scene
    pat_u, pat_l = config.patterns
    return {
        "name": config.name,
        "kind": "vision",
        "g": float(config.g),
        "repeats": config.repeats,
        "robot": {"model": config.robot.model, "params": dict(config.robot.params), **config.robot.spec},
        **({"camera": {"file": "camera.json"}} if sc.rig is None else {"cameras": {"rig": RIG_NAME}}),
        "targets": {
            "fixed": {
                "board": sc.fixed_board.size,
                "square_mm": sc.fixed_board.square_mm,
                "fixed2base": sc.fixed2base.tolist(),
            },
            "mobile": {
                "board": sc.mobile_board.size,
                "square_mm": sc.mobile_board.square_mm,
                "point_mm": [float(v) for v in sc.point_mm],
                "mobile2tcp": sc.mobile2tcp.tolist(),
            },
        },
        "positions": _positions_table(config),
        "loads": {
            "cases": [
                {"force_n": [float(v) for v in ld.force], "label": ld.label or f"load {i}"}
                for i, ld in enumerate(config.loads, start=1)
            ],
            **(
                {"point_mm": [float(v) for v in config.robot.load_point_mm]}
                if any(config.robot.load_point_mm)
                else {}
            ),
        },
        "images": {
            "unloaded": pat_u,
            "loaded": pat_l,
            "pairing": "mean-reference" if config.robot_stays else "pairs",
        },
    }


def _truth_positions(config: SimConfig, plan: CampaignPlan) -> list[dict[str, Any]]:
    """truth.json's positions: K (the forces'), its det and eigenvalues, K6 at the tool point
    (``K_tcp``) of a 6x6 field, the platform's orientation (``orientation_deg``) when turned."""
    positions = []
    for i, (p, K3, K) in enumerate(zip(config.positions, plan.K3, plan.K, strict=True), start=1):
        w = np.linalg.eigvalsh(0.5 * (K3 + K3.T))
        entry = {"index": i, "position": p, "K": K3, "det": float(np.linalg.det(K3)), "eigenvalues": w}
        if K.shape == (6, 6):
            entry["K_tcp"] = K
        if config.orientations is not None:
            entry["orientation_deg"] = np.degrees(config.orientations[i - 1])
        positions.append(entry)
    return positions


def _truth_dict(
    config: SimConfig, plan: CampaignPlan, command: str, calibration: dict[str, Any]
) -> dict[str, Any]:
    sc = config.scene
    rb = config.robot
    positions = _truth_positions(config, plan)
    images = [
        {
            "file": j.file,
            "position": j.position,
            "load": j.load,
            "repeat": j.repeat,
            "state": j.state,
            "commanded_mm": j.commanded_mm,
            "tcp2base": j.tcp2base,
            "gain": j.gain,
            "offset_dn": j.offset_dn,
        }
        for j in plan.jobs
    ]
    return to_jsonable(
        {
            "format": TRUTH_FORMAT,
            "kind": "vision",
            "generator": {"tool": "stiffmap simulate", "version": __version__, "command": command},
            "seed": config.seed,
            "units": "mm, N, rad; K in N/mm (K_tcp: 6x6 at the tool point, blocks N/mm, N, N*mm/rad)",
            "camera": sc.camera.to_dict(),
            "calibrated_camera": calibration.pop("camera"),
            "calibration": calibration,
            "cam2base": sc.cam2base,
            **(
                {}
                if sc.rig is None
                else {"rig": sc.rig.to_dict(), "calibrated_rig": calibration.pop("rig", None)}
            ),
            "targets": {
                "fixed": {
                    "board": sc.fixed_board.size,
                    "square_mm": sc.fixed_board.square_mm,
                    "margin_mm": sc.margin_mm,
                    "fixed2base": sc.fixed2base,
                },
                "mobile": {
                    "board": sc.mobile_board.size,
                    "square_mm": sc.mobile_board.square_mm,
                    "margin_mm": sc.margin_mm,
                    "mobile2tcp": sc.mobile2tcp,
                    "point_mm": sc.point_mm,
                },
            },
            "robot": {
                "model": rb.model,
                "params": rb.params,
                "field": f"{plan.K.shape[1]}x{plan.K.shape[2]}",
                "repeatability_mm": rb.repeatability_mm,
                "repeatability_rad": rb.repeatability_rad,
                "jitter_mm": rb.jitter_mm,
                "load_point_mm": list(rb.load_point_mm),
            },
            "loads": [{"force_n": ld.force, "label": ld.label} for ld in config.loads],
            "repeats": config.repeats,
            "photometry": {
                **asdict(config.photometry),
                "gain_jitter": config.gain_jitter,
                "offset_jitter_dn": config.offset_jitter_dn,
                "format": config.image_format,
            },
            "positions": positions,
            "corners_file": CORNERS_NAME,
            "images": images,
        }
    )


# ------------------------------------------------------------------ calibration

_PARAMS = ("fx", "fy", "cx", "cy")


def _true_camera(note: str) -> CalibrationSummary:
    return CalibrationSummary(False, note, 0, 0, float("nan"), {}, {})


def calibrate_from_views(
    out: Path,
    config: SimConfig,
    views: tuple[CalibrationView, ...],
    *,
    workers: int | Backend = 1,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[CalibrationSummary, CalibrationResult, dict[str, Any]]:
    """Render the calibration views into ``out`` and calibrate the camera from them.

    The calibration is ``stiffmap calibrate``'s (:func:`stiffmap.vision.files.calibrate_files`,
    model ``k3``, or ``fisheye`` for a fisheye camera, views whose RMS is an outlier left out);
    the views are named relative to
    ``out`` in the camera's ``views``, as ``stiffmap calibrate calibration/*.png`` run in the
    campaign directory names them.

    Returns
    -------
    summary : CalibrationSummary
    result : CalibrationResult
        Its camera (with ``cov``) is what camera.json is to hold; its views are named
        relative to ``out``.
    rendered : dict
        Per view file: ``({"file", "calibration": {"board2cam", "corners_px"}}, bytes written)``
        (the true pose and corners).

    Raises
    ------
    InputError
        The calibration failed (too few views with the board found), or its camera fails
        camera.json's plausibility checks (naming the calibration folder).
    """
    rendered = render_calibration_images(out, config, views, workers=workers, progress=progress)
    paths = [out / v.file for v in views]
    try:
        res = calibrate_files(paths, CALIBRATION_BOARD, model=calibration_model(config.scene.camera))
    except InputError as e:
        raise InputError(
            f"the camera could not be calibrated from the {len(views)} rendered calibration views: "
            + e.detail,
            source=str(out / CALIBRATION_DIR),
        ) from None
    names = {str(p): v.file for p, v in zip(paths, views, strict=True)}
    cam = replace(
        res.camera, views=tuple({**d, "image": names.get(d["image"], d["image"])} for d in res.camera.views)
    )
    problems = plausibility_problems(cam)
    if problems:
        raise InputError(
            "the camera calibrated from the rendered views is implausible: "
            + "; ".join(f"{k}: {what}" for k, what in problems),
            source=str(out / CALIBRATION_DIR),
        )
    true = config.scene.camera
    err = {k: float(getattr(cam, k) - getattr(true, k)) for k in _PARAMS}
    rel = {k: err[k] / float(getattr(true, k)) for k in _PARAMS}
    summary = CalibrationSummary(True, "", len(views), res.n_used, float(cam.rms_px), rel, err)
    res = replace(
        res, camera=cam, views=tuple(replace(v, image=names.get(v.image, v.image)) for v in res.views)
    )
    return summary, res, rendered


def calibrate_rig_from_views(
    out: Path,
    config: SimConfig,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[CalibrationSummary, RigCalibrationResult, dict[str, Any]]:
    """Render a rig's calibration views into ``out/calibration/CAMERA/`` and calibrate the rig.

    The views are :func:`~stiffmap.sim.calibration_views.rig_calibration_views` of the scene's
    true rig (``config.calibration_views`` in all: the board seen by every camera at once, and
    one view per camera alone), rendered with the campaign's photometry and format; the
    calibration is ``stiffmap calibrate-rig``'s (:func:`stiffmap.vision.files.calibrate_rig_files`,
    model ``k3``, views matched by their number).

    Returns
    -------
    summary : CalibrationSummary
        Against the first camera (its fx, fy, cx, cy).
    result : RigCalibrationResult
    rendered : dict
        Per view file ``({"file", "calibration": {"board2cam", "corners_px"}}, bytes)``.

    Raises
    ------
    InputError
        The rig could not be calibrated from the rendered views (naming the folder).
    """
    rig = config.scene.rig
    views = rig_calibration_views(
        rig, config.calibration_views, rng=seeded_generator(config.seed, *RIG_POSE_KEY)
    )
    rendered: dict[str, Any] = {}
    total = sum(len(v.cameras) for v in views)
    if progress:
        progress(0, total)
    for v in views:
        for k, r in enumerate(render_rig_view(rig, v, photometry=config.photometry, seed=config.seed)):
            if r is None:
                continue
            name = rig.cameras[k].name
            rel = calibration_view_file(v.index, config.image_format, camera=name)
            data = encode_image(r.image, config.image_format, jpeg_quality=config.jpeg_quality)
            atomic_write_bytes(out / rel, data)
            t = r.targets[0]
            rendered[rel] = (
                {"file": rel, "calibration": {"board2cam": t.board2cam, "corners_px": t.corners_px}},
                len(data),
            )
            if progress:
                progress(len(rendered), total)
    try:
        res = calibrate_rig_files(
            [(c.name, out / CALIBRATION_DIR / c.name) for c in rig.cameras],
            CALIBRATION_BOARD,
            model=calibration_model(rig.cameras[0].camera),
        )
    except InputError as e:
        raise InputError(
            f"the rig could not be calibrated from the {len(views)} rendered calibration views: " + e.detail,
            source=str(out / CALIBRATION_DIR),
        ) from None
    cam, true = res.rig.cameras[0].camera, rig.cameras[0].camera
    err = {k: float(getattr(cam, k) - getattr(true, k)) for k in _PARAMS}
    rel = {k: err[k] / float(getattr(true, k)) for k in _PARAMS}
    rms = float(np.sqrt(np.mean([c.camera.rms_px**2 for c in res.rig.cameras])))
    summary = CalibrationSummary(True, "", len(views), int(min(res.n_used)), rms, rel, err)
    return summary, res, rendered


def _rig_calibration_truth(
    summary: CalibrationSummary, result: RigCalibrationResult, true: Rig
) -> dict[str, Any]:
    """truth.json's ``calibration`` for a rig (with ``camera`` and ``rig`` popped out)."""
    per_camera = []
    for t, c in zip(true.cameras, result.rig.cameras, strict=True):
        d = invert_transform(t.cam2rig) @ c.cam2rig
        per_camera.append(
            {
                "name": t.name,
                "relative_error": {
                    k: (getattr(c.camera, k) - getattr(t.camera, k)) / getattr(t.camera, k) for k in _PARAMS
                },
                "cam2rig_translation_error_mm": float(np.linalg.norm(d[:3, 3])),
                "cam2rig_rotation_error_deg": float(
                    np.degrees(np.linalg.norm(rotvec_from_matrix(d[:3, :3])))
                ),
            }
        )
    return {
        "camera_json": "calibrated rig",
        "tool": f"stiffmap calibrate-rig (vision.files.calibrate_rig_files, model {CALIBRATION_MODEL})",
        "board": CALIBRATION_BOARD.size,
        "square_mm": CALIBRATION_BOARD.square_mm,
        "margin_mm": CALIBRATION_MARGIN_MM,
        "n_views": summary.n_views,
        "n_used": list(result.n_used),
        "rms_px": summary.rms_px,
        "relative_error": summary.relative_error,
        "error_px": summary.error_px,
        "cameras": per_camera,
        "camera": result.rig.cameras[0].camera.to_dict(),
        "rig": result.rig.to_dict(),
    }


def _calibration_truth(
    summary: CalibrationSummary, result: CalibrationResult | None, views: tuple[CalibrationView, ...]
) -> dict[str, Any]:
    """truth.json's ``calibration`` (with ``camera``, popped into ``calibrated_camera``)."""
    if result is None:
        return {"camera_json": "true camera", "note": summary.note, "camera": None}
    found = {v.image: v.to_dict() for v in result.views}
    return {
        "camera_json": "calibrated",
        "tool": f"stiffmap calibrate (stiffmap.vision.files.calibrate_files, model {CALIBRATION_MODEL})",
        "board": CALIBRATION_BOARD.size,
        "square_mm": CALIBRATION_BOARD.square_mm,
        "margin_mm": CALIBRATION_MARGIN_MM,
        "n_views": summary.n_views,
        "n_used": summary.n_used,
        "rms_px": summary.rms_px,
        "relative_error": summary.relative_error,
        "error_px": summary.error_px,
        "views": [
            {
                "file": v.file,
                "board2cam": v.board2cam,
                "used": found.get(v.file, {}).get("used", False),
                "rms_px": found.get(v.file, {}).get("rms_px"),
                "reason": found.get(v.file, {}).get("reason", "not calibrated"),
                "gain": v.gain,
                "offset_dn": v.offset_dn,
            }
            for v in views
        ],
        "camera": result.camera.to_dict(),
    }


# ------------------------------------------------------------------ writing


def write_campaign(
    out_dir: str | os.PathLike,
    config: SimConfig,
    *,
    workers: int = 1,
    force: bool = False,
    render_images: bool = True,
    progress: Callable[[int, int], None] | None = None,
    command: str = "",
    plan: CampaignPlan | None = None,
    dask: str | None = None,
) -> SimSummary:
    """Simulate a campaign and write its directory.

    Parameters
    ----------
    out_dir : path-like
        Created if needed; must be empty (or a previous simulation, with ``force``).
    config : SimConfig
    workers : int
        Processes rendering images (1: in this process); with ``dask="local"``, the local
        cluster's workers. The images do not depend on it.
    force : bool
        Overwrite a previous simulation in ``out_dir``.
    render_images : bool
        False: write the spec, camera and truth but no images (for tests of the
        measurement chain on the true corners); camera.json is then the true camera
        (there is nothing to calibrate from).
    progress : callable, optional
        Called as ``progress(done, total)`` after each finished image (the calibration
        views first, then the campaign's images).
    command : str
        The command line, recorded in truth.json.
    plan : CampaignPlan, optional
        ``plan_campaign(config)`` if already computed.
    dask : str, optional
        Render on a Dask cluster (:mod:`stiffmap.parallel`): ``"local"`` or a scheduler's
        address. Workers that see ``out_dir`` at the same path write the images there;
        others send them back and this process writes them.

    Returns
    -------
    SimSummary

    Raises
    ------
    InputError
        Output directory not usable; a position where the robot model has no
        stiffness or a board leaves the image (naming it); the camera could not be
        calibrated from the rendered views (naming the calibration folder).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    if int(workers) < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    if plan is None:
        plan = plan_campaign(config)
    prepare_output_dir(out, force)
    with connected(Backend(int(workers), dask, start_method="spawn")) as backend:
        return _write_campaign(out, config, backend, render_images, progress, command, plan, t0)


def _no_calibration_note(config: SimConfig) -> str:
    """Why a simulated campaign holds the true camera (no calibration views rendered)."""
    if config.scene.rig is not None and not config.calibration_views:
        return "no calibration views (calibration_views = 0, --true-camera): rig.json holds the true cameras"
    if config.calibration_views:
        return "truth only: no images to calibrate from"
    return "no calibration views (calibration_views = 0, --true-camera)"


def _write_setup(out: Path, config: SimConfig, plan: CampaignPlan, command: str, result, rig_result) -> None:
    """Write the camera (or rig) calibrated or true, the robot's own files and campaign.toml."""
    rig = config.scene.rig
    if rig is None:
        save_camera(config.scene.camera if result is None else result.camera, out / "camera.json")
    else:
        save_rig(rig if rig_result is None else rig_result.rig, out / RIG_NAME)
    for name, source in config.robot.files.items():  # the robot's own files (a URDF robot's URDF)
        atomic_write_bytes(out / name, source if isinstance(source, bytes) else Path(source).read_bytes())
    spec = CampaignSpec.model_validate(campaign_spec_dict(config, plan))
    header = (
        f"Simulated on the virtual test-bed by {command or 'stiffmap'} (stiffmap {__version__}, "
        f"seed {config.seed}).\n"
        f"The ground truth (true K at every position, every image's poses and corners) is in {TRUTH_NAME}."
    )
    atomic_write_text(out / "campaign.toml", dump_spec(spec, header))


def _write_corners(out: Path, corners: list, rendered_views: dict) -> None:
    """Write the true corners of every image (and calibration view) to ``corners.json.gz``."""
    gz = {"format": TRUTH_FORMAT, "images": corners}
    if rendered_views:
        # In file order (viewNN, per camera folder): the pool finishes views in any order.
        gz["calibration"] = [rendered_views[f][0] for f in sorted(rendered_views)]
    data = json.dumps(to_jsonable(gz), allow_nan=False)
    atomic_write_bytes(out / CORNERS_NAME, gzip.compress(data.encode("utf-8"), mtime=0))


def _write_campaign(
    out: Path,
    config: SimConfig,
    backend: Backend,
    render_images: bool,
    progress: Callable[[int, int], None] | None,
    command: str,
    plan: CampaignPlan,
    t0: float,
) -> SimSummary:
    """:func:`write_campaign` once its output directory is ready and its backend connected."""
    rig = config.scene.rig
    views = plan_calibration_views(config) if render_images and rig is None else ()
    rig_result = None
    jobs = list(plan.jobs)
    n_total = len(views) + (len(jobs) if render_images else 0)
    result = None
    t_cal = time.perf_counter()
    if views:
        cal_progress = None if progress is None else (lambda done, _total: progress(done, n_total))
        calibration, result, rendered_views = calibrate_from_views(
            out, config, views, workers=backend, progress=cal_progress
        )
    elif rig is not None and render_images and config.calibration_views:
        cal_progress = None if progress is None else (lambda done, total: progress(done, total + len(jobs)))
        calibration, rig_result, rendered_views = calibrate_rig_from_views(out, config, progress=cal_progress)
        n_total = len(rendered_views) + len(jobs)
    else:
        rendered_views = {}
        calibration = _true_camera(_no_calibration_note(config))
    t_cal = time.perf_counter() - t_cal
    _write_setup(out, config, plan, command, result, rig_result)
    img_progress = None
    if progress is not None:
        img_progress = (
            (lambda done, total: progress(len(rendered_views) + done, n_total)) if render_images else progress
        )
    results = render_campaign_images(
        out, config, jobs, workers=backend, render_images=render_images, progress=img_progress
    )
    _write_corners(out, [results[j.file][0] for j in jobs], rendered_views)
    if rig_result is not None:
        cal_truth = _rig_calibration_truth(calibration, rig_result, rig)
    else:
        cal_truth = _calibration_truth(calibration, result, views)
    truth = _truth_dict(config, plan, command, cal_truth)
    atomic_write_text(out / TRUTH_NAME, compact_json(truth) + "\n")
    eig = np.linalg.eigvalsh(0.5 * (plan.K3 + np.swapaxes(plan.K3, 1, 2)))
    return SimSummary(
        out_dir=out,
        n_positions=len(config.positions),
        n_loads=len(config.loads),
        repeats=config.repeats,
        n_images=len(jobs) if render_images else 0,
        images_rendered=bool(render_images),
        bytes_written=int(sum(n for _, n in results.values()) + sum(n for _, n in rendered_views.values())),
        seconds=time.perf_counter() - t0,
        principal_range=(float(eig.min()), float(eig.max())),
        files=tuple(f for f in _OWN_FILES if (out / f).is_file()),
        calibration=calibration,
        calibration_seconds=t_cal,
    )
