"""``--camera SOURCE``: which camera a capture reads, and the simulated camera of a campaign.

=====================  ==========================================================
``sim``                the virtual test-bed (:func:`simulated_camera`); options after a colon:
                       ``sim:fps=5,time_constant_s=0.1,frequency_hz=1.7,seed=2``
``0``, ``1``, ...      a camera device (OpenCV)
``rtsp://...``         a stream (OpenCV)
``video.mp4``          a video file (OpenCV)
``folder/``            the images of a folder, in name order
``genicam:PRODUCER.cti[#SERIAL]``   an industrial camera through harvesters (optional extra)
=====================  ==========================================================

The simulated camera of a campaign made by ``stiffmap simulate`` or ``stiffmap demo`` renders
the scene its ``truth.json`` describes (true camera, boards and their poses, photometry, the
robot's repeatability and vibration, the true stiffness at each position); for another campaign
it renders the demo's scene (:func:`stiffmap.sim.scene.demo_scene`) with the demo's Delta robot.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..camera import CameraModel, load_camera
from ..campaign.spec import CampaignSpec
from ..campaign.truth import TRUTH_NAME, load_truth
from ..errors import InputError
from ..sim.live_camera import SimulatedCamera, TableField
from ..sim.render import Photometry
from ..sim.robot import VirtualRobot, delta_robot
from ..sim.scene import Scene, demo_scene
from ..targets import Chessboard, parse_board_size
from .sources import CameraSource, FolderSource, GenICamSource, OpenCVSource

__all__ = ["open_camera", "simulated_camera", "SIM_OPTIONS"]

#: What ``sim:KEY=VALUE,...`` may set.
SIM_OPTIONS = ("fps", "frequency_hz", "time_constant_s", "settled_mm", "move_ring_mm", "seed")

#: The highest frame rate of the simulated camera, frames per second (a real camera's is lower;
#: at 1e9 frames a second the settling the capture waits for would take a billion frames).
MAX_SIM_FPS = 1000.0


def _sim_options(text: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        key, sep, val = item.partition("=")
        key = key.strip()
        if not sep or key not in SIM_OPTIONS:
            raise InputError(
                f"--camera sim:{text}: expected KEY=VALUE items with KEY one of {', '.join(SIM_OPTIONS)}"
            )
        try:
            v = float(val)
        except ValueError:
            raise InputError(f"--camera sim:{text}: {key} = {val!r} is not a number") from None
        if not np.isfinite(v) or v < 0 or (v == 0 and key not in ("seed", "move_ring_mm")):
            raise InputError(f"--camera sim:{text}: {key} must be a positive number, got {val!r}")
        if key == "fps" and v > MAX_SIM_FPS:
            raise InputError(
                f"--camera sim:{text}: fps must be at most {MAX_SIM_FPS:g} frames per second, got {val!r}"
            )
        out[key] = int(v) if key == "seed" else v
    return out


def _board(d: dict) -> Chessboard:
    return Chessboard(*parse_board_size(str(d["board"])), float(d["square_mm"]))


def simulated_camera(root: Path, spec: CampaignSpec, **options) -> SimulatedCamera:
    """The virtual test-bed as the live camera of a campaign (see the module docstring).

    Raises
    ------
    InputError
        A simulated campaign with a rig, or a truth.json that cannot be read.
    """
    root = Path(root)
    if (root / TRUTH_NAME).is_file():
        truth = load_truth(root)
        d = truth.data
        src = str(root / TRUTH_NAME)
        if d.get("kind") != "vision" or d.get("rig") is not None:
            raise InputError("the simulated camera renders one camera of a vision campaign", source=src)
        if any(np.any(e.get("orientation_deg", 0.0)) for e in d.get("positions", ())):
            raise InputError(
                "the simulated camera holds the platform level; this campaign turns it (positions.poses)",
                source=src,
            )
        try:
            t = d["targets"]
            scene = Scene(
                camera=truth.camera,
                cam2base=truth.cam2base,
                fixed_board=_board(t["fixed"]),
                fixed2base=np.asarray(t["fixed"]["fixed2base"], dtype=float),
                mobile_board=_board(t["mobile"]),
                mobile2tcp=np.asarray(t["mobile"]["mobile2tcp"], dtype=float),
                margin_mm=float(t["mobile"].get("margin_mm", 10.0)),
            )
            rb = d["robot"]
            key = "K_tcp" if rb.get("field") == "6x6" else "K"
            K = np.array([e[key] for e in d["positions"]], dtype=float)
            robot = VirtualRobot(
                field=TableField(truth.positions, K),
                repeatability_mm=float(rb["repeatability_mm"]),
                repeatability_rad=float(rb["repeatability_rad"]),
                jitter_mm=float(rb["jitter_mm"]),
                load_point_mm=tuple(rb.get("load_point_mm", (0.0, 0.0, 0.0))),
            )
            names = {f.name for f in dataclasses.fields(Photometry)}
            ph = {k: v for k, v in d.get("photometry", {}).items() if k in names}
            if "white_balance" in ph:
                ph["white_balance"] = tuple(ph["white_balance"])
            photometry = Photometry(**ph)
            seed = int(d.get("seed", 0))
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(
                f"cannot build the simulated camera: {type(e).__name__} {e}", source=src
            ) from None
    else:
        camera = None
        if spec.camera is not None and (root / spec.camera.file).is_file():
            camera = load_camera(root / spec.camera.file)
        scene = demo_scene(_true_like(camera))
        robot = delta_robot()
        photometry = Photometry()
        seed = 0
    opts = {"seed": seed, **options}
    return SimulatedCamera(scene, robot, photometry=photometry, name="simulated camera", **opts)


def _true_like(camera: CameraModel | None) -> CameraModel | None:
    """The campaign's camera without its uncertainty (the simulated camera renders through it)."""
    if camera is None:
        return None
    return CameraModel(
        camera.image_size, camera.fx, camera.fy, camera.cx, camera.cy, camera.dist, model=camera.model
    )


def open_camera(option: str, root: Path, spec: CampaignSpec) -> CameraSource:
    """The camera source ``--camera`` names (see the module docstring); not yet open.

    Raises
    ------
    InputError
        Naming the option and what was expected.
    """
    opt = str(option).strip()
    if opt == "sim" or opt.startswith("sim:"):
        return simulated_camera(root, spec, **_sim_options(opt[4:]))
    if opt.isdigit():
        return OpenCVSource(int(opt))
    if opt.lower().startswith("genicam:"):
        rest = opt[len("genicam:") :]
        producer, _, serial = rest.partition("#")
        if not producer:
            raise InputError("--camera genicam:PRODUCER.cti[#SERIAL]: the GenTL producer file is missing")
        return GenICamSource(producer, serial or None)
    if "://" in opt:
        return OpenCVSource(opt)
    p = Path(opt)
    if p.is_dir():
        return FolderSource(p)
    if p.is_file():
        return OpenCVSource(opt)
    raise InputError(
        f"--camera {opt!r}: not a camera number, a stream URL, a video file, a folder of images, "
        "genicam:PRODUCER.cti or sim"
    )
