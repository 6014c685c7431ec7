"""Planning a virtual vision campaign: its settings, its images and the disk space they need.

What a user chooses -- the robot and its stiffness field, the positions, the loads,
the camera, the noise and the image format -- becomes a
:class:`~stiffmap.sim.testbed.SimConfig` (:func:`vision_config`);
:func:`plan_simulation` then plans every image
(:func:`~stiffmap.sim.testbed.plan_campaign`) and estimates the disk space the
images will take (:func:`image_bytes`), refusing a simulation that would fill the
disk before anything is written. ``stiffmap simulate`` is these two calls and
:func:`stiffmap.campaign.simulated.write_campaign`.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..loads import LoadCase
from .photometry import Photometry
from .robot import VirtualRobot, with_rotational_compliance
from .scene import Scene, default_scene, with_cameras
from .testbed import DEFAULT_CALIBRATION_VIEWS, CampaignPlan, SimConfig, plan_campaign

__all__ = [
    "BYTES_PER_PIXEL",
    "vision_config",
    "rig_scene",
    "image_bytes",
    "SimulationPlan",
    "plan_simulation",
]

#: Bytes per pixel of a noisy 8-bit image (measured on the default scene: PNG ~0.50, JPEG q95 ~0.18).
BYTES_PER_PIXEL = {"png": 0.55, "jpeg": 0.2}


# Longer than ~80 lines for its interface alone: 21 keyword settings (those of `stiffmap simulate`)
# and their documentation take ~75 lines; the body (~40 lines) builds the robot, photometry and scene.
def vision_config(
    robot: VirtualRobot,
    positions,
    loads: Sequence[LoadCase],
    camera: CameraModel | None = None,
    *,
    rot_stiffness_nmm_per_rad: float | None = None,
    load_point_mm=(0.0, 0.0, 0.0),
    repeatability_mm: float = 0.02,
    jitter_mm: float = 0.001,
    noise: bool = True,
    blur_px: float = 0.8,
    clutter: bool = False,
    colour: bool = False,
    repeats: int = 3,
    seed: int = 0,
    image_format: str = "png",
    jpeg_quality: int = 95,
    name: str = "virtual test-bed",
    calibration_views: int = DEFAULT_CALIBRATION_VIEWS,
    cameras: int = 1,
    camera_angle_deg: float = 60.0,
    scene: Scene | None = None,
) -> SimConfig:
    """The settings of a simulated vision campaign, as ``stiffmap simulate`` takes them.

    Parameters
    ----------
    robot : VirtualRobot
        The robot whose stiffness field, model name and parameters are simulated
        (e.g. :func:`~stiffmap.sim.robot.delta_robot`); its positioning noise is
        replaced by ``repeatability_mm`` and ``jitter_mm``.
    positions : array_like, shape (n, 3), mm, or (n, 6)
        Commanded positions of the tool point, base frame; or poses (x, y, z mm, roll,
        pitch, yaw rad) of a robot whose platform turns (:attr:`VirtualRobot.turns`): its
        platform, and the board on it, held at that orientation.
    loads : sequence of LoadCase
    camera : CameraModel, optional
        Default: the reference camera. The boards are those of
        :func:`~stiffmap.sim.scene.default_scene`.
    rot_stiffness_nmm_per_rad : float, optional
        Give the platform this rotational stiffness: a 6x6 field at the tool point
        (:func:`~stiffmap.sim.robot.with_rotational_compliance`).
    load_point_mm : (float, float, float)
        Where the loads act, tool frame, mm (it matters with a 6x6 field only).
    repeatability_mm, jitter_mm : float
        1 sigma per axis of the position error on reaching a position, and of each
        image's own, mm.
    noise : bool
        Sensor noise, vignetting and image-to-image illumination changes (gain 3 %,
        black level 1 DN); False: only the optics blur and 8-bit rounding.
    blur_px, clutter, colour
        As :class:`~stiffmap.sim.photometry.Photometry`.
    repeats, seed, image_format, jpeg_quality, name, calibration_views
        As :class:`~stiffmap.sim.testbed.SimConfig` (``calibration_views``: views of the
        calibration board the campaign's camera is calibrated from; 0: the true camera).
    cameras : int
        Cameras looking at the robot (:func:`rig_scene`): 1, or a rig of several.
    camera_angle_deg : float
        With several cameras, the angle between the first and the last about the vertical.
    scene : Scene, optional
        The camera, boards and their mounting (default: :func:`~stiffmap.sim.scene.default_scene`
        of ``camera``; ``camera`` is then not used).

    Returns
    -------
    SimConfig

    Raises
    ------
    InputError
        A setting out of range (the message names it).
    """
    P = np.asarray(positions, dtype=np.float64)
    orientations = None
    if P.ndim == 2 and P.shape[1] == 6:  # poses: level ones are positions (written as a list)
        P, orientations = P[:, :3], (P[:, 3:] if np.any(P[:, 3:]) else None)
    try:
        field = robot.field
        if rot_stiffness_nmm_per_rad is not None:
            field = with_rotational_compliance(field, rot_stiffness_nmm_per_rad)
        vr = VirtualRobot(
            field,
            repeatability_mm=repeatability_mm,
            jitter_mm=jitter_mm,
            load_point_mm=load_point_mm,
            model=robot.model,
            params=robot.params,
            spec=robot.spec,
            files=robot.files,
        )
        if noise:
            ph = Photometry(blur_px=blur_px, clutter=clutter, colour=colour)
        else:
            ph = Photometry.noise_free(blur_px=blur_px, clutter=clutter, colour=colour)
        scene = default_scene(camera) if scene is None else scene
        if int(cameras) != 1:
            scene = rig_scene(scene, int(cameras), P, angle_deg=camera_angle_deg)
        return SimConfig(
            scene=scene,
            robot=vr,
            positions=P,
            orientations=orientations,
            loads=tuple(loads),
            repeats=repeats,
            seed=seed,
            photometry=ph,
            image_format=image_format,
            jpeg_quality=jpeg_quality,
            name=name,
            calibration_views=calibration_views,
            gain_jitter=0.03 if noise else 0.0,
            offset_jitter_dn=1.0 if noise else 0.0,
        )
    except InputError:
        raise
    except ValueError as e:
        raise InputError(str(e)) from None


#: Margin beyond ``SimConfig.border_px`` that :func:`rig_scene` keeps between each board and
#: the image border (room for the displacements and the robot's repeatability), px.
RIG_MARGIN_PX = 40.0


def rig_scene(scene: Scene, n: int, positions, *, angle_deg: float = 60.0, border_px: float = 20.0) -> Scene:
    """``scene`` seen by ``n`` cameras ``angle_deg`` apart (:func:`~stiffmap.sim.scene.with_cameras`),
    as close as keeps both boards in every camera's view at every position.

    The cameras turned about the vertical see the workspace's depth across: they step back from
    the scene camera's distance (by 5 % steps, up to twice) until every board stays
    ``border_px`` + :data:`RIG_MARGIN_PX` inside each image at every position.

    Raises
    ------
    ValueError
        ``n`` < 1, or no distance up to twice the scene camera's keeps the boards in view.
    """
    if n < 1 or n > 8:
        raise ValueError(f"cameras must be 1 to 8, got {n}")
    if n == 1:
        return scene
    if not 0.0 < float(angle_deg) <= 120.0:
        raise ValueError(f"the angle between the cameras must be in (0, 120] degrees, got {angle_deg}")
    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    why = ""
    for f in np.arange(1.0, 2.0001, 0.05):
        sc = with_cameras(scene, n, angle_deg=angle_deg, distance_scale=float(f))
        try:
            sc.check_visible(P, border_px=border_px + RIG_MARGIN_PX)
            return sc
        except ValueError as e:
            why = str(e)
    raise ValueError(
        f"{n} cameras {angle_deg:g} degrees apart cannot see both boards at every position ({why})"
    )


def image_bytes(config: SimConfig, n_images: int) -> float:
    """Estimated size of ``n_images`` images of ``config`` (its camera, colour and format), bytes
    (with a rig, ``n_images`` image sets of one image per camera).

    ``n w h sqrt(channels) b`` with ``b`` from :data:`BYTES_PER_PIXEL` (an estimate: the
    size depends on the noise and on what the image shows).
    """
    colour = config.photometry.colour
    px = sum(c.image_size[0] * c.image_size[1] for _, c, _ in config.scene.cameras)
    return n_images * px * (3 if colour else 1) ** 0.5 * BYTES_PER_PIXEL[config.image_format]


@dataclass(frozen=True)
class SimulationPlan:
    """A simulated campaign planned and checked, before anything is written.

    Attributes
    ----------
    config : SimConfig
    plan : CampaignPlan
        Every image's true poses and the true stiffness
        (:func:`~stiffmap.sim.testbed.plan_campaign`).
    n_images : int
        Campaign images to render (0 when only the truth is written).
    bytes_needed : float
        Their estimated size with the calibration views' (:func:`image_bytes`), bytes.
    n_calibration_views : int
        Calibration views to render (0 when only the truth is written, or with the true
        camera).
    """

    config: SimConfig
    plan: CampaignPlan
    n_images: int
    bytes_needed: float
    n_calibration_views: int = 0


def plan_simulation(
    config: SimConfig,
    out_dir: str | os.PathLike,
    *,
    render_images: bool = True,
    advice: str = "simulate fewer positions, load cases or repeats, or write JPEG images",
) -> SimulationPlan:
    """Plan every image of ``config`` and check that they fit on the disk of ``out_dir``.

    Parameters
    ----------
    config : SimConfig
    out_dir : path-like
        Where the campaign will be written (it need not exist yet: the free space is
        that of its nearest existing parent).
    render_images : bool
        False: only the truth will be written (no images, no disk check).
    advice : str
        What the message of a full disk suggests (the command line names its options).

    Returns
    -------
    SimulationPlan

    Raises
    ------
    InputError
        A position where the robot model has no stiffness, or a board that leaves the
        image (naming the position, load and repeat); or images that would take more
        than 95 % of the free disk space (naming ``out_dir``).
    """
    plan = plan_campaign(config)
    n_images = len(plan.jobs) if render_images else 0
    n_views = config.calibration_views if render_images else 0
    need = image_bytes(config, n_images + n_views)
    out = Path(out_dir)
    probe = out if out.exists() else next((p for p in out.resolve().parents if p.exists()), Path("."))
    free = shutil.disk_usage(probe).free
    if need > 0.95 * free:
        raise InputError(
            f"{n_images + n_views} images need about {need / 1e9:.1f} GB but only "
            f"{free / 1e9:.1f} GB are free; " + advice,
            source=str(out_dir),
        )
    return SimulationPlan(
        config=config, plan=plan, n_images=n_images, bytes_needed=need, n_calibration_views=n_views
    )
