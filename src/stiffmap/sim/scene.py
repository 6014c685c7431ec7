"""Placing targets in front of a camera, and the virtual test-bed's default scene.

The default scene (:func:`default_scene`) is the reference study's set-up seen
from the front: the robot base frame has z up and the platform below it
(positions z = -200 ... -400 mm); the fixed board is the study's motor-support
board (``fixed2base`` of its section 3.1: a vertical board, x along the base x,
y pointing down, facing -y); the mobile board hangs 50 mm in front of the
platform, facing the same way; the camera stands 1.28 m in front of the robot
(y = -1280 mm), turned 8 degrees about the vertical and looking 10.4 degrees down,
so that both boards are fully visible, 85 px from the image border or more, at
every position of the ``paper48`` grid.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..camera import CameraModel, reference_camera
from ..geometry import as_transform, concat, invert_transform, matrix_from_rotvec, transform_from
from ..rig import Rig, RigCamera
from ..targets import Chessboard
from .reflectance import Target

__all__ = [
    "board_pose_at_pixel",
    "spread_poses",
    "Scene",
    "scene_around",
    "default_scene",
    "demo_scene",
    "arm_scene",
    "ARM_SCENE_SHIFT_MM",
    "hexapod_scene",
    "HEXAPOD_SCENE_SHIFT_MM",
    "with_cameras",
    "two_camera_rig",
    "FIXED2BASE_REFERENCE",
]

#: The reference study's motor-support board in the robot base frame (its section 3.1), mm.
FIXED2BASE_REFERENCE = np.array(
    [[1.0, 0.0, 0.0, -75.63], [0.0, 0.0, 1.0, 188.10], [0.0, -1.0, 0.0, 31.00], [0.0, 0.0, 0.0, 1.0]]
)
FIXED2BASE_REFERENCE.setflags(write=False)


@dataclass(frozen=True)
class Scene:
    """Camera and boards of a virtual vision test-bed.

    Attributes
    ----------
    camera : CameraModel
    cam2base : ndarray, shape (4, 4)
        Camera pose in the robot base frame, mm.
    fixed_board, mobile_board : Chessboard
    fixed2base : ndarray, shape (4, 4)
        Fixed board in the base frame, mm.
    mobile2tcp : ndarray, shape (4, 4)
        Mobile board on the platform (tcp frame), mm.
    margin_mm : float
        White border printed around each board's squares, mm.
    rig : Rig or None
        Several cameras: the rig (its first camera is ``camera``, and ``cam2base`` is then the
        rig frame's pose in the base frame, the first camera's). None: ``camera`` alone.
    """

    camera: CameraModel
    cam2base: np.ndarray
    fixed_board: Chessboard
    fixed2base: np.ndarray
    mobile_board: Chessboard
    mobile2tcp: np.ndarray
    margin_mm: float = 10.0
    rig: Rig | None = None

    def __post_init__(self) -> None:
        for k in ("cam2base", "fixed2base", "mobile2tcp"):
            T = as_transform(getattr(self, k), k).copy()
            T.setflags(write=False)
            object.__setattr__(self, k, T)
        if self.rig is not None and self.rig.cameras[0].camera.key != self.camera.key:
            raise ValueError("a scene's camera must be its rig's first camera")
        if self.fixed_board.size == self.mobile_board.size:
            raise ValueError(
                f"the fixed and mobile boards are both {self.fixed_board.size}: "
                "a campaign tells them apart by their size"
            )

    @property
    def point_mm(self) -> np.ndarray:
        """The tool point (tcp origin) in the mobile board frame, mm, shape (3,)."""
        return invert_transform(self.mobile2tcp)[:3, 3]

    @property
    def cameras(self) -> tuple[tuple[str, CameraModel, np.ndarray], ...]:
        """Every camera: (name, camera, cam2base); one (``"camera"``) without a rig."""
        if self.rig is None:
            return (("camera", self.camera, self.cam2base),)
        return tuple((c.name, c.camera, self.cam2base @ c.cam2rig) for c in self.rig.cameras)

    def targets(self, tcp2base, camera: int = 0) -> list[Target]:
        """The fixed and the mobile board as render targets of camera ``camera`` (index), for the
        platform at ``tcp2base``."""
        base2cam = invert_transform(self.cameras[camera][2])
        fixed2cam = concat(self.fixed2base, base2cam)
        mobile2cam = concat(concat(self.mobile2tcp, as_transform(tcp2base, "tcp2base")), base2cam)
        return [
            Target(self.fixed_board, fixed2cam, name="fixed", margin_mm=self.margin_mm),
            Target(self.mobile_board, mobile2cam, name="mobile", margin_mm=self.margin_mm),
        ]

    def outline_pixels(self, tcp2base, camera: int = 0) -> dict[str, np.ndarray]:
        """Pixels of each board's printed outline (corners of the margin) in camera ``camera``'s
        image, shape (4, 2) each."""
        out = {}
        cam = self.cameras[camera][1]
        for tg in self.targets(tcp2base, camera):
            x0, y0, x1, y1 = tg.texture().extent
            q = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
            P = q @ tg.board2cam[:3, :3].T + tg.board2cam[:3, 3]
            if np.any(P[:, 2] <= 0):
                out[tg.name] = np.full((4, 2), np.nan)
            else:
                out[tg.name] = cam.project(P)
        return out

    def visibility_problem(self, tcp2base, *, border_px: float = 20.0) -> str | None:
        """Why a board is not fully visible with the platform at ``tcp2base`` (None if it is).

        A board must lie in front of every camera, its printed outline at least
        ``border_px`` from the image border.
        """
        for k, (cname, cam, _) in enumerate(self.cameras):
            w, h = cam.image_size
            of = f" of camera {cname}" if self.rig is not None else ""
            for name, uv in self.outline_pixels(tcp2base, k).items():
                if not np.all(np.isfinite(uv)):
                    return f"the {name} board reaches behind the camera{of.replace(' of camera', '')}"
                if (
                    uv[:, 0].min() < border_px
                    or uv[:, 1].min() < border_px
                    or uv[:, 0].max() > w - 1 - border_px
                    or uv[:, 1].max() > h - 1 - border_px
                ):
                    return (
                        f"the {name} board leaves the image{of} (or comes within {border_px:g} px of its "
                        "border)"
                    )
        return None

    def check_visible(self, positions, *, border_px: float = 20.0, slack_mm: float = 0.0) -> None:
        """Raise ValueError naming the first position at which a board leaves the image.

        Parameters
        ----------
        positions : array_like, shape (n, 3)
            Platform positions (tcp origin in the base frame), mm.
        border_px : float
            Required distance of each board's outline from the image border, px.
        slack_mm : float
            Extra displacement of the platform, in every direction, that must keep it visible.
        """
        P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        shifts = [np.zeros(3)]
        if slack_mm > 0:
            shifts += [slack_mm * s for s in np.vstack([np.eye(3), -np.eye(3)])]
        for i, p in enumerate(P):
            for d in shifts:
                why = self.visibility_problem(transform_from(np.eye(3), p + d), border_px=border_px)
                if why:
                    raise ValueError(f"position {i + 1} ({', '.join(f'{v:g}' for v in p)}) mm: {why}")


def _turn(axis: str, deg: float) -> np.ndarray:
    """The rotation by ``deg`` degrees about the frame's ``axis`` ("x", "y" or "z"), (3, 3)."""
    r = np.zeros(3)
    r["xyz".index(axis)] = np.radians(deg)
    return matrix_from_rotvec(r)


def default_scene(camera: CameraModel | None = None) -> Scene:
    """The reference set-up seen from the front (see the module docstring).

    Fixed board 9x6 inner corners, mobile board 6x5 (both 10 mm squares, 10 mm
    white margin; 6x5 rather than a square board so that its colours fix its
    orientation). The tool point is 50 mm behind the mobile board, 15 mm above
    its first row of corners, centred.
    """
    cam = reference_camera() if camera is None else camera
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # cam x, y, z in base
    R = _turn("z", 8.0) @ R0 @ _turn("x", -10.4)
    cam2base = transform_from(R, [300.0, -1280.0, 0.0])
    mobile2tcp = transform_from(FIXED2BASE_REFERENCE[:3, :3], [-25.0, -50.0, -15.0])
    return Scene(
        camera=cam,
        cam2base=cam2base,
        fixed_board=Chessboard(9, 6, 10.0),
        fixed2base=FIXED2BASE_REFERENCE,
        mobile_board=Chessboard(6, 5, 10.0),
        mobile2tcp=mobile2tcp,
        margin_mm=10.0,
    )


#: Where the arm's scene puts the demo scene's base frame, in the arm's base frame (mm): the
#: demo scene's view of the Delta's grid becomes a view of the arm's test box
#: (:func:`stiffmap.models.arm6.positions20`).
ARM_SCENE_SHIFT_MM = (525.0, 0.0, 700.0)


def arm_scene(camera: CameraModel | None = None) -> Scene:
    """The six-joint arm's scene: :func:`demo_scene` moved to the arm's test box.

    The same camera, boards and mounting of the mobile board on the platform as the
    demo (a 15x14 board 50 mm in front of the tool point), all moved by
    :data:`ARM_SCENE_SHIFT_MM`: the camera is 1.25 m in front of the box x 400-650,
    y -150-150, z 300-500 mm in front of the arm, and the fixed board stands on a
    post fixed to the arm's base, above and behind that box (at about (525, 188, 700) mm).
    The tool's orientation is the same at every position (the arm's tool points
    down), so the tcp frame keeps the base's axes, as for a translational robot.
    """
    sc = demo_scene(camera)
    shift = transform_from(np.eye(3), ARM_SCENE_SHIFT_MM)
    return replace(sc, cam2base=shift @ sc.cam2base, fixed2base=shift @ sc.fixed2base)


#: Where the hexapod's scene puts the demo scene's base frame, in the hexapod's base frame
#: (mm): the demo's view of the Delta's grid (z -200 ... -400) becomes a view of the space
#: above the hexapod's base (z 400 ... 200), where its platform moves.
HEXAPOD_SCENE_SHIFT_MM = (0.0, 0.0, 600.0)


def hexapod_scene(camera: CameraModel | None = None) -> Scene:
    """A hexapod's scene: :func:`demo_scene` moved above the hexapod's base.

    The same camera, boards and mounting of the mobile board on the platform as the demo
    (a 15x14 board 50 mm in front of the tool point, the centre of the platform), all moved
    up by :data:`HEXAPOD_SCENE_SHIFT_MM`; the fixed board stands on a post behind the
    hexapod. The test-bed holds the platform level (the tcp frame keeps the base's axes)
    unless its positions are poses (``SimConfig.orientations``): the board then turns with
    the platform; orientations of about 10 degrees keep it in view.
    """
    sc = demo_scene(camera)
    shift = transform_from(np.eye(3), HEXAPOD_SCENE_SHIFT_MM)
    return replace(sc, cam2base=shift @ sc.cam2base, fixed2base=shift @ sc.fixed2base)


#: The middle of the region the demo scene's camera sees well (the ``paper48`` grid's centre), mm.
DEMO_VIEW_CENTRE_MM = (0.0, 0.0, -300.0)


def scene_around(positions, camera: CameraModel | None = None) -> Scene:
    """:func:`demo_scene` moved so that it looks at ``positions``: a user's robot on the test-bed.

    The camera, the fixed board on its post and the mounting of the mobile board on the
    platform (the tcp frame) are the demo's, all moved by the vector from
    :data:`DEMO_VIEW_CENTRE_MM` to the middle of the positions' bounding box, as
    :func:`arm_scene` does for the six-joint arm's box. The region seen well is the demo's,
    about 400 x 400 x 200 mm (x, y, z); the campaign's plan names a position where a board
    leaves the image.

    Parameters
    ----------
    positions : array_like, shape (N, 3), mm
        The measured point's positions, robot base frame.
    camera : CameraModel, optional
    """
    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    centre = 0.5 * (P.min(axis=0) + P.max(axis=0))
    shift = transform_from(np.eye(3), centre - np.asarray(DEMO_VIEW_CENTRE_MM))
    sc = demo_scene(camera)
    return replace(sc, cam2base=shift @ sc.cam2base, fixed2base=shift @ sc.fixed2base)


def demo_scene(camera: CameraModel | None = None) -> Scene:
    """The demo's scene: the reference set-up with a larger board on the platform.

    Same camera and fixed board as :func:`default_scene` (the study's motor-support
    board), but a 15x14 mobile board (10 mm squares, 160 x 150 mm) centred on the
    tool point, 50 mm in front of it, and the camera moved to 1.25 m in front of the
    robot (at (100, -1250, -50) mm, turned 4 degrees about the vertical, looking 9
    degrees down), the nearest pose that keeps both boards in view and apart at every
    ``paper48`` position (1.01-1.47 m from the mobile board). A static camera that
    sees the whole grid is that far away, and the depth of a planar board is measured
    through its apparent size: the larger board (several times the corner spread of
    a 6x5 one) is what brings the displacement along the line of sight to a few
    micrometres, so that K is recovered within a few percent at every position.
    """
    cam = reference_camera() if camera is None else camera
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    R = _turn("z", 4.0) @ R0 @ _turn("x", -9.0)
    mobile = Chessboard(15, 14, 10.0)
    mobile2tcp = transform_from(FIXED2BASE_REFERENCE[:3, :3], [-70.0, -50.0, 65.0])
    return Scene(
        camera=cam,
        cam2base=transform_from(R, [100.0, -1250.0, -50.0]),
        fixed_board=Chessboard(9, 6, 10.0),
        fixed2base=FIXED2BASE_REFERENCE,
        mobile_board=mobile,
        mobile2tcp=mobile2tcp,
        margin_mm=10.0,
    )


def with_cameras(
    scene: Scene,
    n: int,
    *,
    angle_deg: float = 60.0,
    pivot_mm=(0.0, 0.0, -310.0),
    distance_scale: float = 1.0,
    names=None,
) -> Scene:
    """The scene seen by ``n`` copies of its camera spread about the vertical (a rig).

    The cameras turn about the base frame's z axis through the point of the scene camera's
    optical axis nearest ``pivot_mm`` (base frame; default the middle of the ``paper48`` grid),
    from -angle/2 to +angle/2 relative to the scene's camera, at ``distance_scale`` times the
    scene camera's distance from that point; each keeps its downward look, and all look at that
    point. The first camera's frame is the rig frame.

    Parameters
    ----------
    scene : Scene
        One camera.
    n : int
        Cameras (1: the scene itself).
    angle_deg : float
        Angle between the first and the last camera about the vertical, degrees.
    pivot_mm : array_like, shape (3,)
    distance_scale : float
        The cameras' distance from the pivot, relative to the scene camera's.
    names : sequence of str, optional
        Default ``cam1``, ``cam2``...

    Returns
    -------
    Scene
        With ``rig`` set (exact ``cam2rig``: the test-bed's truth) and ``camera``,
        ``cam2base`` those of the first camera.
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"a scene needs at least one camera, got {n}")
    if n == 1:
        return scene
    names = [f"cam{k + 1}" for k in range(n)] if names is None else [str(x) for x in names]
    if len(names) != n:
        raise ValueError(f"{len(names)} names for {n} cameras")
    C = scene.cam2base
    axis = C[:3, 2]
    c0 = C[:3, 3]
    t = float(np.dot(np.asarray(pivot_mm, dtype=np.float64) - c0, axis))
    pivot = c0 + t * axis
    angles = np.linspace(-angle_deg / 2.0, angle_deg / 2.0, n)
    poses = []
    for a in angles:
        Rz = _turn("z", float(a))
        poses.append(transform_from(Rz @ C[:3, :3], pivot + distance_scale * (Rz @ (c0 - pivot))))
    base2rig = invert_transform(poses[0])
    rig = Rig(
        tuple(
            RigCamera(name, scene.camera, concat(P, base2rig))
            if k
            else RigCamera(name, scene.camera, np.eye(4))
            for k, (name, P) in enumerate(zip(names, poses, strict=True))
        )
    )
    return replace(scene, cam2base=poses[0], rig=rig)


def two_camera_rig(
    camera: CameraModel | None = None,
    distance_mm: float = 650.0,
    angle_deg: float = 60.0,
    *,
    right_camera: CameraModel | None = None,
) -> Rig:
    """The test-bed's default rig: two cameras ``angle_deg`` apart, looking at one point.

    The first camera, ``"left"``, is the rig frame; it looks along its z axis at the point
    (0, 0, ``distance_mm``). The second, ``"right"``, is at the same distance from that
    point, turned about the rig's y axis (down in the images) so that it stands to the
    left camera's right (+x) and looks at the point too: its optical axis makes
    ``angle_deg`` with the left one's, the baseline is 2 d sin(angle / 2) (650 mm at the
    defaults). The ``cam2rig`` are exact (the truth of a simulated rig).

    Parameters
    ----------
    camera : CameraModel, optional
        Both cameras' model (default the reference camera).
    distance_mm : float
        Distance of each camera from the point both look at, mm.
    angle_deg : float
        Angle between the optical axes, degrees, in (0, 180).
    right_camera : CameraModel, optional
        Another model for the right camera.

    Returns
    -------
    Rig
    """
    d = float(distance_mm)
    a = float(angle_deg)
    if not (np.isfinite(d) and d > 0):
        raise ValueError(f"distance_mm must be a positive number of mm, got {distance_mm!r}")
    if not (np.isfinite(a) and 0 < a < 180):
        raise ValueError(f"angle_deg must be in (0, 180) degrees, got {angle_deg!r}")
    left = reference_camera() if camera is None else camera
    right = left if right_camera is None else right_camera
    R = _turn("y", -a)
    target = np.array([0.0, 0.0, d])
    return Rig(
        (
            RigCamera("left", left, np.eye(4)),
            RigCamera("right", right, transform_from(R, target - d * R[:, 2])),
        )
    )


def board_pose_at_pixel(
    camera: CameraModel,
    pixel,
    distance_mm: float,
    board_point_mm,
    *,
    tilt_deg: float = 0.0,
    tilt_axis_deg: float = 0.0,
    spin_deg: float = 0.0,
) -> np.ndarray:
    """``board2cam`` that puts a board point on the ray of a pixel, tilted and spun.

    The board, facing the camera (its z axis along the optical axis), is spun
    about its z axis by ``spin_deg``, then tilted by ``tilt_deg`` about an axis
    in the image plane at ``tilt_axis_deg`` from the camera's x axis; then the
    board point ``board_point_mm`` is moved onto the ray of ``pixel`` at depth
    ``distance_mm``.

    Parameters
    ----------
    camera : CameraModel
    pixel : array_like, shape (2,)
        (u, v), px.
    distance_mm : float
        Depth (camera z) of the board point, mm.
    board_point_mm : array_like, shape (2,)
        (x, y) in the board frame, mm (e.g. the board's centre).

    Returns
    -------
    board2cam : ndarray, shape (4, 4)
    """
    uv = np.asarray(pixel, dtype=np.float64)
    p = np.asarray(board_point_mm, dtype=np.float64)
    if uv.shape != (2,) or p.shape != (2,) or not (np.all(np.isfinite(uv)) and np.all(np.isfinite(p))):
        raise ValueError(
            f"pixel and board_point_mm must be finite (2,) vectors, got {pixel!r}, {board_point_mm!r}"
        )
    if not (np.isfinite(distance_mm) and distance_mm > 0):
        raise ValueError(f"distance_mm must be a positive number of mm, got {distance_mm!r}")
    ray = camera.rays_from_pixels(uv)
    a = np.radians(tilt_axis_deg)
    tilt = matrix_from_rotvec(np.radians(tilt_deg) * np.array([np.cos(a), np.sin(a), 0.0]))
    R = tilt @ _turn("z", spin_deg)
    t = np.array([ray[0], ray[1], 1.0]) * float(distance_mm) - R @ np.array([p[0], p[1], 0.0])
    return transform_from(R, t)


def spread_poses(
    camera: CameraModel,
    board,
    *,
    grid: tuple[int, int] = (3, 3),
    distance_mm: float = 700.0,
    max_tilt_deg: float = 45.0,
    margin: float = 0.16,
) -> list[np.ndarray]:
    """Board poses spread over the whole image, tilted up to ``max_tilt_deg`` (deterministic).

    The board's centre is put on the rays of a ``grid`` = (columns, rows) of
    image points between ``margin`` and ``1 - margin`` of the width and height.
    Tilts cycle through max, max, 2/3 max, max, 0, max, 1/3 max, ... about
    axes turning by 40 degrees from pose to pose; spins turn by 23 degrees.
    Suited to calibration sets and to the renderer's truth test.

    Parameters
    ----------
    camera : CameraModel
    board : Chessboard or CharucoBoard
    grid : (int, int)
    distance_mm : float
        Depth of the board centres, mm.
    max_tilt_deg : float
    margin : float
        Fraction of the image left at each border for the board's centre.

    Returns
    -------
    list of ndarray, shape (4, 4)
        ``board2cam`` of each pose, row by row.
    """
    chess = getattr(board, "chessboard", board)
    x0, y0, x1, y1 = chess.extent_mm()
    centre = (0.5 * (x0 + x1), 0.5 * (y0 + y1))
    w, h = camera.image_size
    fr = (1.0, 1.0, 2.0 / 3.0, 1.0, 0.0, 1.0, 1.0 / 3.0, 1.0, 2.0 / 3.0)
    out = []
    k = 0
    for fv in np.linspace(margin, 1 - margin, grid[1]):
        for fu in np.linspace(margin, 1 - margin, grid[0]):
            pix = (fu * (w - 1), fv * (h - 1))
            out.append(
                board_pose_at_pixel(
                    camera,
                    pix,
                    distance_mm,
                    centre,
                    tilt_deg=max_tilt_deg * fr[k % len(fr)],
                    tilt_axis_deg=40.0 * k,
                    spin_deg=23.0 * k - 30.0,
                )
            )
            k += 1
    return out
