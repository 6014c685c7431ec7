"""Calibration views of the virtual test-bed: a board at the poses a careful user takes.

A lab calibrates its camera before a campaign; the test-bed does the same, so that a
simulated campaign is measured with a camera calibrated from images, as a real one is,
not with the true camera (``docs/simulation.md``). :func:`careful_poses` places the
calibration board (:data:`CALIBRATION_BOARD`: 11x8 inner corners of 25 mm, 300 x 225 mm
of squares with a 25 mm white margin, an A3 print on a flat plate) as the OpenCV and
Bouguet (Camera Calibration Toolbox for Matlab) advice has it:

- the board covers roughly a quarter to a half of the image (three distances, from the
  fraction of the image the printed board covers when facing the camera:
  :data:`COVERAGES`; tilted, it covers 20-50 %);
- its centre goes towards every part of the image in turn -- the four corners, the
  centre, the four edges -- as far as the whole board stays inside the image (into a
  corner until it touches both borders), so that the corners, where the distortion is
  strongest, are covered;
- it is tilted by up to :data:`MAX_TILT_DEG` about axes turning from view to view (the
  tilts are what fix the focal length), and spun a little;
- every board is wholly inside the image, ``border_px`` from its border.

A seeded jitter (a few degrees, a few percent of distance) makes the poses those of a
hand, not of a robot; the same seed gives the same poses. :func:`plan_calibration_views`
plans a campaign's views (file names, poses, per-view illumination) from its
:class:`~stiffmap.sim.testbed.SimConfig`, and :func:`render_calibration_view` renders one
with the campaign's own photometry, so that the calibration sees what the campaign images
see. The calibration itself (detection, Zhang's method) is ``stiffmap.vision``'s, called by
:mod:`stiffmap.campaign.simulated`: this layer does not import it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..camera import CameraModel, UndistortionError
from ..geometry import invert_transform, mean_transform
from ..rig import Rig
from ..targets import Chessboard
from .photometry import Photometry
from .render import Rendering, Target, encode_image, render
from .scene import board_pose_at_pixel
from .testbed import SimConfig, seeded_generator

__all__ = [
    "CALIBRATION_BOARD",
    "CALIBRATION_DIR",
    "CALIBRATION_MARGIN_MM",
    "COVERAGES",
    "MAX_TILT_DEG",
    "CalibrationView",
    "careful_poses",
    "plan_calibration_views",
    "render_calibration_view",
    "calibration_view_file",
    "RigView",
    "RIG_POSE_KEY",
    "rig_calibration_views",
    "render_rig_view",
]

#: Folder of the calibration views in a campaign directory.
CALIBRATION_DIR = "calibration"
#: The calibration board: 11x8 inner corners (12 x 9 squares) of 25 mm.
CALIBRATION_BOARD = Chessboard(11, 8, 25.0)
#: Its white margin, mm (350 x 275 mm printed: an A3 sheet).
CALIBRATION_MARGIN_MM = 25.0
#: Fractions of the image area the printed board (margin included) covers when it faces the
#: camera, at the three distances (tilted, it covers less).
COVERAGES = (0.5, 0.28, 0.38)
#: Largest tilt of the board, degrees.
MAX_TILT_DEG = 42.0
#: Where the board's centre heads for, from the image centre (x right, y down): the four
#: corners first, then the centre and the four edges.
_DIRECTIONS = ((-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (0, -1), (1, 0), (0, 1), (-1, 0))
#: Tilts as fractions of the largest, cycled (7 values against 9 directions: every
#: direction meets several tilts).
_TILTS = (1.0, 0.55, 0.85, 0.3, 1.0, 0.7, 0.9)
#: Spawn keys of the calibration's random draws (position 0: never a campaign image's).
_POSE_KEY = (0, 0, 0, 3)
#: The draw of a rig's calibration poses (beside ``_POSE_KEY``, a single camera's).
RIG_POSE_KEY = (0, 0, 0, 4)
_VIEW_STATE = 2


@dataclass(frozen=True)
class CalibrationView:
    """One calibration image to render and its truth.

    Attributes
    ----------
    file : str
        Path relative to the campaign directory (``calibration/view01.png``).
    index : int
        1-based.
    board2cam : ndarray, shape (4, 4)
        True pose of the calibration board, mm.
    gain, offset_dn : float
        Photometry of this image (illumination change, as the campaign's images have).
    """

    file: str
    index: int
    board2cam: np.ndarray
    gain: float
    offset_dn: float

    @property
    def spawn_key(self) -> tuple[int, int, int, int]:
        return (0, 0, self.index, _VIEW_STATE)


def _distance_for(camera: CameraModel, extent, coverage: float) -> float:
    """Depth at which a board of ``extent`` (mm), facing the camera, covers ``coverage`` of the image, mm."""
    x0, y0, x1, y1 = extent
    w, h = camera.image_size
    return float(np.sqrt(camera.fx * camera.fy * (x1 - x0) * (y1 - y0) / (coverage * w * h)))


def _outline_inside(camera: CameraModel, T: np.ndarray, extent, border_px: float) -> bool:
    """Is the printed board (outline sampled along its sides) in front of the camera and inside?"""
    try:
        uv = camera.project_rectangle(T, extent, samples=17)
    except ValueError:  # behind the camera
        return False
    w, h = camera.image_size
    return bool(
        np.all(np.isfinite(uv))
        and uv[:, 0].min() >= border_px
        and uv[:, 1].min() >= border_px
        and uv[:, 0].max() <= w - 1 - border_px
        and uv[:, 1].max() <= h - 1 - border_px
    )


def _farthest(fits) -> float:
    """Largest t in [0, 1] with ``fits(t)`` (bisection to 1e-6; ``fits(0)`` is true)."""
    if fits(1.0):
        return 1.0
    lo, hi = 0.0, 1.0
    while hi - lo > 1e-6:
        t = 0.5 * (lo + hi)
        lo, hi = (t, hi) if fits(t) else (lo, t)
    return lo


def careful_poses(
    camera: CameraModel,
    n_views: int = 20,
    *,
    board: Chessboard = CALIBRATION_BOARD,
    margin_mm: float = CALIBRATION_MARGIN_MM,
    max_tilt_deg: float = MAX_TILT_DEG,
    border_px: float = 20.0,
    rng: np.random.Generator | None = None,
    fits: Callable[[np.ndarray], bool] | None = None,
) -> list[np.ndarray]:
    """Poses of a calibration board that a careful user takes (see the module docstring).

    View k heads for direction ``k mod 9`` (corners, centre, edges) at distance
    ``k // 9 mod 3`` of :data:`COVERAGES`, tilted by a cycled fraction of
    ``max_tilt_deg`` about an axis turning by the golden angle (137.5 degrees) from view
    to view. Its centre is then slid from the image centre towards its direction, then
    along each axis of that direction on its own (into a corner until two sides of the
    board touch the border), as far as the whole printed board (margin included) stays
    ``border_px`` inside the image; a board that does not fit even at the centre is moved
    away until it does.

    Parameters
    ----------
    camera : CameraModel
        The true camera (the poses depend on its image size and focal length only
        through the distances and the fit).
    n_views : int
        Number of poses (>= 1).
    board : Chessboard
    margin_mm : float
        White margin printed around the squares, mm.
    max_tilt_deg : float
        Largest tilt of the board from facing the camera, degrees (< 80).
    border_px : float
        Distance of every board's outline from the image border, px.
    rng : numpy Generator, optional
        A small jitter of each pose (tilt +/- 2 degrees, axis and spin +/- 8 degrees,
        distance +/- 4 %); None: none.
    fits : callable, optional
        ``fits(board2cam) -> bool``: a further condition every pose meets (e.g. the board
        seen by the other cameras of a rig, :func:`rig_calibration_views`); the board
        slides only as far as it holds, and is moved away until it holds at the centre.

    Returns
    -------
    list of ndarray, shape (4, 4)
        ``board2cam`` of each view, mm.

    Raises
    ------
    ValueError
        ``n_views`` < 1, a tilt out of range, or a board that fits nowhere in the image.
    """
    n = int(n_views)
    if n < 1:
        raise ValueError(f"n_views must be >= 1, got {n_views!r}")
    if not (np.isfinite(max_tilt_deg) and 0 <= max_tilt_deg < 80):
        raise ValueError(f"max_tilt_deg must be in [0, 80), got {max_tilt_deg!r}")
    x0, y0, x1, y1 = board.extent_mm()
    m = float(margin_mm)
    extent = (x0 - m, y0 - m, x1 + m, y1 + m)
    w, h = camera.image_size
    mid = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    place = _Placement(
        camera, extent, (0.5 * (x0 + x1), 0.5 * (y0 + y1)), border_px, fits, mid, mid - border_px
    )
    poses = []
    for k in range(n):
        d = np.asarray(_DIRECTIONS[k % len(_DIRECTIONS)], dtype=np.float64)
        dist, angles = _view_start(camera, extent, k, max_tilt_deg, rng)
        T = _place(place, k, d, dist, angles)
        T.setflags(write=False)
        poses.append(T)
    return poses


@dataclass(frozen=True)
class _Placement:
    """What every view of :func:`careful_poses` is placed in: the camera, the printed board's
    extent and centre (mm), the border kept (px), a further condition, the image's centre and
    the half-size a view slides within (px)."""

    camera: CameraModel
    extent: tuple[float, float, float, float]
    centre_mm: tuple[float, float]
    border_px: float
    fits: Callable[[np.ndarray], bool] | None
    mid: np.ndarray
    half: np.ndarray

    def pose(self, pixel, dist: float, angles: tuple[float, float, float]) -> np.ndarray:
        """``board2cam`` with the board's centre seen at ``pixel``, ``dist`` mm away, at (tilt,
        tilt axis, spin) ``angles`` (degrees)."""
        tilt, axis, spin = angles
        return board_pose_at_pixel(
            self.camera, pixel, dist, self.centre_mm, tilt_deg=tilt, tilt_axis_deg=axis, spin_deg=spin
        )

    def fits_at(self, pixel, dist: float, angles: tuple[float, float, float]) -> bool:
        """The whole printed board inside the image (and ``fits``) at that pose."""
        try:
            T = self.pose(pixel, dist, angles)
            return _outline_inside(self.camera, T, self.extent, self.border_px) and (
                self.fits is None or self.fits(T)
            )
        except UndistortionError:  # a fisheye's pixel that sees 90 degrees or more off axis
            return False


def _view_start(camera, extent, k: int, max_tilt_deg: float, rng) -> tuple[float, tuple[float, float, float]]:
    """View k's distance (mm) and (tilt, tilt axis, spin) in degrees, jittered with ``rng``."""
    golden = 180.0 * (3.0 - np.sqrt(5.0))
    dist = _distance_for(camera, extent, COVERAGES[(k // len(_DIRECTIONS)) % len(COVERAGES)])
    tilt = max_tilt_deg * _TILTS[k % len(_TILTS)]
    axis = golden * k + 20.0
    spin = 15.0 * np.sin(2.1 * k)
    if rng is not None:
        j = rng.uniform(-1.0, 1.0, 4)
        tilt = float(np.clip(tilt + 2.0 * j[0], 0.0, max_tilt_deg))
        axis += 8.0 * j[1]
        spin += 8.0 * j[2]
        dist *= 1.0 + 0.04 * j[3]
    return dist, (tilt, axis, spin)


def _place(place: _Placement, k: int, d: np.ndarray, dist: float, angles) -> np.ndarray:
    """View k's pose: moved away until the board fits at the image centre, then slid towards its
    direction ``d``, then along each axis on its own (into a corner: until both sides touch the
    border), as far as it stays inside."""
    for _ in range(60):  # farther until the board fits at the image centre
        if place.fits_at(place.mid, dist, angles):
            break
        dist *= 1.06
    else:
        w, h = place.camera.image_size
        raise ValueError(f"view {k + 1}: the board fits nowhere in the {w}x{h} px image")
    pixel = place.mid.copy()
    half = place.half
    along_x, along_y = np.array([d[0], 0.0]) * half, np.array([0.0, d[1]]) * half
    for step in (d * half, along_x, along_y, along_x, along_y):
        if np.any(step):
            t = _farthest(lambda t, p0=pixel, e=step, z=dist: place.fits_at(p0 + t * e, z, angles))
            pixel = pixel + t * step
    return place.pose(pixel, dist, angles)


def calibration_view_file(index: int, image_format: str = "png", camera: str | None = None) -> str:
    """``calibration/viewNN.png`` (or ``.jpg``), 1-based; a rig camera's: ``calibration/CAMERA/viewNN.png``
    (a folder per camera, the view's number in the name: how ``calibrate-rig`` matches them)."""
    ext = "png" if image_format == "png" else "jpg"
    folder = CALIBRATION_DIR if camera is None else f"{CALIBRATION_DIR}/{camera}"
    return f"{folder}/view{int(index):02d}.{ext}"


def plan_calibration_views(config: SimConfig, n_views: int | None = None) -> tuple[CalibrationView, ...]:
    """The calibration views of a campaign: careful poses, files, per-view illumination.

    Parameters
    ----------
    config : SimConfig
        Its camera, seed, photometry jitter, image format and ``border_px``.
    n_views : int, optional
        Default ``config.calibration_views`` (0: none).

    Returns
    -------
    tuple of CalibrationView
    """
    n = config.calibration_views if n_views is None else int(n_views)
    if n <= 0:
        return ()
    cam = config.scene.camera
    poses = careful_poses(cam, n, border_px=config.border_px, rng=seeded_generator(config.seed, *_POSE_KEY))
    ph = config.photometry
    views = []
    for k, T in enumerate(poses, start=1):
        rng = seeded_generator(config.seed, 0, 0, k, _VIEW_STATE + 2)
        gain = ph.gain * max(1.0 + config.gain_jitter * rng.standard_normal(), 0.05)
        offset = max(ph.offset_dn + config.offset_jitter_dn * rng.standard_normal(), 0.0)
        views.append(
            CalibrationView(calibration_view_file(k, config.image_format), k, T, float(gain), float(offset))
        )
    return tuple(views)


def render_calibration_view(config: SimConfig, view: CalibrationView) -> tuple[bytes, Rendering]:
    """Render and encode one calibration view with the campaign's camera and photometry.

    Returns
    -------
    data : bytes
        The encoded image (the campaign's format and JPEG quality).
    rendering : Rendering
        The image and the board's true pose and corners (target name ``"calibration"``).
    """
    ph = replace(config.photometry, gain=view.gain, offset_dn=view.offset_dn)
    target = Target(CALIBRATION_BOARD, view.board2cam, name="calibration", margin_mm=CALIBRATION_MARGIN_MM)
    r = render(
        config.scene.camera, [target], photometry=ph, seed=seeded_generator(config.seed, *view.spawn_key)
    )
    return encode_image(r.image, config.image_format, jpeg_quality=config.jpeg_quality), r


# ----------------------------------------------------------------------------------- rigs
#: Largest angle between a board's normal and a camera's line of sight to it in a rig's
#: shared views, degrees (beyond, the corners are too foreshortened to be worth a view).
RIG_MAX_INCIDENCE_DEG = 65.0


@dataclass(frozen=True)
class RigView:
    """One calibration view of a rig: the board's pose and the cameras that take an image of it.

    Attributes
    ----------
    index : int
        1-based.
    board2rig : ndarray, shape (4, 4)
        True pose of the board in the rig frame, mm.
    cameras : tuple of int
        Indices of the cameras that take an image of this view (every camera for a shared
        view, one for a view of one camera).
    """

    index: int
    board2rig: np.ndarray
    cameras: tuple[int, ...]

    def board2cam(self, rig: Rig, k: int) -> np.ndarray:
        """The board's true pose in camera ``k``'s frame, mm."""
        return invert_transform(rig.cameras[k].cam2rig) @ self.board2rig


def _incidence_ok(T: np.ndarray, centre_mm, max_deg: float) -> bool:
    """Does the camera see the board's front within ``max_deg`` of its normal (board2cam ``T``)?"""
    c = T[:3, :3] @ np.array([centre_mm[0], centre_mm[1], 0.0]) + T[:3, 3]
    return float(T[:3, 2] @ c) > np.cos(np.radians(max_deg)) * float(np.linalg.norm(c))


def _virtual_camera(rig: Rig, max_tilt_deg: float | None, max_incidence_deg: float):
    """The virtual camera of a rig's shared views (at the mean of the cameras' poses): its pose
    in the rig, each camera's pose of it, and the largest tilt of a shared view (degrees)."""
    c2r = [c.cam2rig for c in rig.cameras]
    virt2rig = mean_transform(c2r)
    virt2cam = [invert_transform(T) @ virt2rig for T in c2r]
    spread = max(
        float(np.degrees(np.arccos(np.clip(T[2, 2], -1.0, 1.0)))) for T in virt2cam
    )  # angle between the virtual and each camera's optical axis
    tilt = (
        min(MAX_TILT_DEG, max(max_incidence_deg - spread - 5.0, 5.0))
        if max_tilt_deg is None
        else max_tilt_deg
    )
    return virt2rig, virt2cam, tilt


def _seen_by_all(rig: Rig, board2cams, centre, extent, max_incidence_deg: float, border_px: float) -> bool:
    """Does every camera see the whole board (``board2cams``: its pose in each), facing it
    within ``max_incidence_deg``?"""
    for c, T in zip(rig.cameras, board2cams, strict=True):
        if not (
            _incidence_ok(T, centre, max_incidence_deg) and _outline_inside(c.camera, T, extent, border_px)
        ):
            return False
    return True


# Longer than ~80 lines for its documentation: what a careful user does with a rig, the
# parameters and raises take ~60 lines; the body (~35 lines) is the shared views, then each camera's.
def rig_calibration_views(
    rig: Rig,
    n_views: int = 15,
    *,
    n_single: int = 1,
    board: Chessboard = CALIBRATION_BOARD,
    margin_mm: float = CALIBRATION_MARGIN_MM,
    max_tilt_deg: float | None = None,
    max_incidence_deg: float = RIG_MAX_INCIDENCE_DEG,
    border_px: float = 20.0,
    rng: np.random.Generator | None = None,
) -> list[RigView]:
    """Calibration views of a rig at the poses a careful user takes (:func:`careful_poses`).

    Most views are shared: the board seen whole by every camera at once, each camera
    ``border_px`` inside its image and within ``max_incidence_deg`` of facing it. They are
    :func:`careful_poses` of a virtual camera (the first camera's model) at the mean of the
    cameras' poses, slid towards every part of that camera's image as far as every real
    camera still sees the board. Shared views cannot reach the corners of each camera's
    image when the cameras look from different directions: a careful user then adds a few
    views for each camera alone, the board in that camera's image corners (``n_single``
    per camera: the first :func:`careful_poses` of that camera, into its corners).

    Parameters
    ----------
    rig : Rig
        The true rig.
    n_views : int
        Number of views in all: shared views, then ``n_single`` per camera.
    n_single : int
        Views per camera seen by that camera only (>= 0).
    board : Chessboard
    margin_mm : float
        White margin printed around the squares, mm.
    max_tilt_deg : float, optional
        Largest tilt of a shared view from facing the virtual camera (default 42 degrees,
        less when the cameras look from directions so different that a tilted board would
        be seen beyond ``max_incidence_deg`` by one of them).
    max_incidence_deg : float
        See above, degrees.
    border_px : float
        Distance of every board's outline from the image border, px.
    rng : numpy Generator, optional
        Jitter of the poses (:func:`careful_poses`).

    Returns
    -------
    list of RigView
        The shared views first (every camera), then each camera's own.

    Raises
    ------
    ValueError
        Fewer views than the single ones plus two shared, or no pose seen by every camera.
    """
    n_cam = len(rig)
    n_single = int(n_single)
    n_shared = int(n_views) - n_cam * n_single
    if n_single < 0 or n_shared < 2:
        raise ValueError(
            f"{n_views} views with {n_single} per camera alone for {n_cam} cameras leave "
            f"{n_shared} shared views; a rig calibration needs at least 2"
        )
    x0, y0, x1, y1 = board.extent_mm()
    m = float(margin_mm)
    extent = (x0 - m, y0 - m, x1 + m, y1 + m)
    centre = (0.5 * (x0 + x1), 0.5 * (y0 + y1))
    virt2rig, virt2cam, tilt = _virtual_camera(rig, max_tilt_deg, max_incidence_deg)

    def seen_by_all(board2virt: np.ndarray) -> bool:
        return _seen_by_all(
            rig, (T @ board2virt for T in virt2cam), centre, extent, max_incidence_deg, border_px
        )

    shared = careful_poses(
        rig.cameras[0].camera,
        n_shared,
        board=board,
        margin_mm=margin_mm,
        max_tilt_deg=tilt,
        border_px=border_px,
        rng=rng,
        fits=seen_by_all,
    )
    views = [RigView(i + 1, virt2rig @ T, tuple(range(n_cam))) for i, T in enumerate(shared)]
    for k, c in enumerate(rig.cameras):
        if n_single == 0:
            break
        own = careful_poses(
            c.camera, n_single, board=board, margin_mm=margin_mm, border_px=border_px, rng=rng
        )
        views += [RigView(len(views) + 1, c.cam2rig @ T, (k,)) for T in own]
    for v in views:
        v.board2rig.setflags(write=False)
    return views


def render_rig_view(
    rig: Rig,
    view: RigView,
    *,
    board: Chessboard = CALIBRATION_BOARD,
    margin_mm: float = CALIBRATION_MARGIN_MM,
    photometry: Photometry | None = None,
    seed: int = 0,
) -> tuple[Rendering | None, ...]:
    """Render one rig view through each camera that takes it (None for the others).

    Camera k's image is ``render(camera_k, [Target(board, board2cam_k)])`` with the noise of
    seed (``seed``, view index, k).
    """
    out: list[Rendering | None] = []
    for k, c in enumerate(rig.cameras):
        if k not in view.cameras:
            out.append(None)
            continue
        target = Target(board, view.board2cam(rig, k), name="calibration", margin_mm=margin_mm)
        out.append(
            render(
                c.camera, [target], photometry=photometry, seed=seeded_generator(seed, 0, view.index, k + 1)
            )
        )
    return tuple(out)
