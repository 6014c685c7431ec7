"""``stiffmap simulate`` as a function: a virtual campaign of a test-bed robot, with its truth.

A robot kind's test-bed (:class:`~stiffmap.kinds.registry.TestBed`) says what measures it:
a camera (rendered images of a vision campaign, :func:`simulate_camera_campaign`, written
by :mod:`stiffmap.campaign.simulated`) or a displacement sensor (recordings of a sensor
campaign, :func:`simulate_sensor_campaign`, :mod:`stiffmap.campaign.simulated_sensor`).
:func:`simulate_campaign` takes either. What the request holds is what the command line
gives, as texts (positions, loads, parameters); a wrong one is a
:class:`~stiffmap.errors.FieldError` naming the request's field, which the command line
words as its option.

Example, a small simulated campaign of the Delta (no images: its truth only)::

    >>> import tempfile
    >>> from stiffmap.campaign.simulate import SimulationRequest, CameraSimOptions, simulate_campaign
    >>> tmp = tempfile.TemporaryDirectory()
    >>> s = simulate_campaign(tmp.name, SimulationRequest(select="1,2", repeats=1),
    ...                       camera=CameraSimOptions(truth_only=True))
    >>> (s.n_positions, s.n_loads, s.n_images)  # 2 positions x 9 load cases, no image written
    (2, 9, 0)
    >>> sorted(s.files)
    ['camera.json', 'campaign.toml', 'truth.json', 'truth_corners.json.gz']
    >>> tmp.cleanup()
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..camera import load_camera
from ..errors import FieldError, InputError
from ..kinds import (
    DEFAULT_TESTBED,
    ROBOT_KINDS,
    OwnSetup,
    RobotDescription,
    RobotKind,
    TestBed,
    build_robot,
    float_params,
    positions_from_text,
    robot_kind,
)
from ..loads import PRESETS, load_design, scaled_loads
from ..models.presets import select_positions
from ..parallel import Backend, local_workers
from ..sim.plan import SimulationPlan, plan_simulation, vision_config
from ..sim.robot import translational_stiffness
from ..sim.scene import scene_around
from ..sim.testbed import DEFAULT_CALIBRATION_VIEWS, SimConfig
from ..stiffness import LARGE_DISPLACEMENT_MM
from ..units import G_REFERENCE_PAPER
from .simulated import SimSummary, check_output_dir, write_campaign
from .simulated_sensor import SensorSimSummary, write_sensor_campaign

__all__ = [
    "SimulationRequest",
    "CameraSimOptions",
    "SensorSimOptions",
    "testbed_robots",
    "testbed",
    "simulate_campaign",
    "simulate_camera_campaign",
    "simulate_sensor_campaign",
    "CAMERA",
    "SENSOR",
]

#: What measures a test-bed robot (:attr:`~stiffmap.kinds.registry.TestBed.instrument`).
CAMERA = "camera"
SENSOR = "sensor"


@dataclass(frozen=True)
class SimulationRequest:
    """What every simulation takes.

    Attributes
    ----------
    robot : str
        A test-bed robot (:func:`testbed_robots`: ``delta``, ``3prr``, ``arm6``...).
    positions : str, optional
        A layout of its kind, a CSV file or a list ``x,y,z;x,y,z`` (default: its test-bed's).
    select : str, optional
        Keep these positions only, 1-based, ``"1,22,48"``.
    repeats : int
        Image pairs per load case (a sensor: recordings per point and axis).
    seed : int
    params : mapping of str to str or float
        Robot model parameters (``k_theta=3e5``).
    name : str, optional
        The campaign's name (default: the test-bed's).
    force : bool
        Overwrite a previous simulation in the output folder.
    command : str
        The command line, recorded in truth.json.
    description : RobotDescription, optional
        A robot of the user's own instead of a test-bed robot (``robot`` is then its file):
        its kind's test-bed takes it (:attr:`~stiffmap.kinds.registry.TestBed.own`), with its
        parameters; its positions are its configurations' measured points unless
        ``positions`` gives points.
    """

    robot: str = DEFAULT_TESTBED
    positions: str | None = None
    select: str | None = None
    repeats: int = 3
    seed: int = 0
    params: Mapping[str, str | float] = field(default_factory=dict)
    name: str | None = None
    force: bool = False
    command: str = ""
    description: RobotDescription | None = None


@dataclass(frozen=True)
class CameraSimOptions:
    """What a simulation seen by cameras takes (:func:`stiffmap.sim.plan.vision_config`).

    ``loads`` is ``paper9`` or a CSV file of forces (N); ``load_point_mm`` where they act
    (tool frame; default the test-bed's); ``camera_file`` a camera.json to simulate instead
    of the reference camera; ``truth_only`` writes no images; ``workers`` 0 is one per CPU.
    """

    loads: str = "paper9"
    camera_file: str | os.PathLike | None = None
    image_format: str = "png"
    jpeg_quality: int = 95
    colour: bool = False
    clutter: bool = False
    noise: bool = True
    blur_px: float = 0.8
    repeatability_mm: float = 0.02
    jitter_mm: float = 0.001
    rot_stiffness_nmm_per_rad: float | None = None
    load_point_mm: tuple[float, float, float] | None = None
    calibration_views: int = DEFAULT_CALIBRATION_VIEWS
    cameras: int = 1
    camera_angle_deg: float = 60.0
    truth_only: bool = False
    workers: int = 0
    dask: str | None = None


@dataclass(frozen=True)
class SensorSimOptions:
    """What a simulation measured by a displacement sensor takes: the axes (``"x,y"``) and the
    recordings' format (csv, tdms, mat)."""

    directions: str = "x,y"
    trace_format: str = "csv"


def testbed_robots() -> dict[str, tuple[RobotKind, TestBed]]:
    """Every test-bed robot of the registry: name -> (its kind, its test-bed)."""
    return {k.testbed.name: (k, k.testbed) for k in ROBOT_KINDS.values() if k.testbed is not None}


def testbed(name: str) -> tuple[RobotKind, TestBed]:
    """The test-bed robot ``name`` (FieldError ``robot`` listing the valid ones)."""
    table = testbed_robots()
    if name not in table:
        raise FieldError("robot", f"unknown test-bed robot {name!r}; expected one of {', '.join(table)}")
    return table[name]


def _own_testbed(request: SimulationRequest) -> tuple[RobotKind, TestBed, np.ndarray, OwnSetup]:
    """A user's own robot on its kind's test-bed: (kind, test-bed, positions (n, 3) mm or poses
    (n, 6), how the test-bed takes it).

    Its positions: those given, else its configurations' measured points, else its kind's
    default (:attr:`~stiffmap.kinds.registry.TestBed.own_setup`: a legs robot's grid about
    its home).

    Raises
    ------
    FieldError
        ``robot``: its kind has no test-bed for a robot of one's own, or not for this one;
        ``positions``: none given and none by default; a wrong value of the description,
        naming its field.
    """
    d = request.description
    kind = robot_kind(d.kind)
    own = None if kind.testbed is None else kind.testbed.own
    if own is None:
        raise FieldError("robot", f"a {kind.name} robot of your own cannot be simulated (no test-bed for it)")
    model = build_robot(d)
    setup = (
        kind.testbed.own_setup(model)
        if kind.testbed.own_setup is not None
        else OwnSetup(rotations=kind.testbed.rotations)
    )
    tb = replace(
        kind.testbed,
        name=str(request.robot),
        positions="",
        robot=lambda params, **kw: own(model, d, **kw),
        rotations=setup.rotations,
        load_point_mm=setup.load_point_mm,
        campaign_name=f"{getattr(getattr(model, 'chain', model), 'name', kind.name)} on the virtual test-bed",
    )
    Q = getattr(model, "configurations", None)
    if request.positions is not None:
        P = _positions(request, kind, tb)
        setup = replace(setup, notes=())  # those of the default positions, not used
    elif Q is not None or setup.positions is not None:
        try:
            P = select_positions(
                model.chain.forward_many(Q)[0] if Q is not None else setup.positions, request.select
            )
        except ValueError as e:
            raise FieldError("select", str(e), value=request.select) from None
        if Q is not None:
            setup = replace(setup, positions_text=f"the measured points of its {len(Q)} joint configurations")
    elif setup.positions_text:
        raise FieldError("positions", f"{setup.positions_text}; give them")
    else:
        raise FieldError(
            "positions", "give the positions: joint configurations (a CSV file) or points the robot reaches"
        )
    return kind, replace(tb, scene=lambda camera: scene_around(P[:, :3], camera)), P, setup


def _request_testbed(
    request: SimulationRequest,
) -> tuple[RobotKind, TestBed, np.ndarray | None, OwnSetup | None]:
    """The request's robot: a test-bed robot (its positions later), or the user's own."""
    if request.description is not None:
        return _own_testbed(request)
    kind, tb = testbed(request.robot)
    return kind, tb, None, None


def _positions(request: SimulationRequest, kind: RobotKind, tb: TestBed) -> np.ndarray:
    """The positions of the request (FieldError ``positions`` or ``select``)."""
    text = request.positions or tb.positions
    # A kind whose description gives its dimension (legs): its platform's positions, 3-D;
    # from a CSV file, with the orientation columns when its platform turns: poses (n, 6).
    as_file = Path(text).suffix.lower() == ".csv" or Path(text).is_file()  # as positions_from_text
    turned = kind.turning_platform and tb.rotations and as_file
    try:
        P = positions_from_text(text, kind.name, 6 if turned else kind.dim or 3)
    except InputError:
        raise
    except ValueError as e:
        raise FieldError("positions", str(e), value=request.positions) from None
    try:
        return select_positions(P, request.select)
    except ValueError as e:
        raise FieldError("select", str(e), value=request.select) from None


def _naming_files(e: InputError, request: SimulationRequest, loads: str | None = None) -> InputError:
    """An error about a position (or a load) read from a file names that file.

    The test-bed numbers what it refuses (``e.items``); when the positions come from a CSV
    file (all of them: no ``select``), position N is its Nth row; when the loads do, the
    loads' file is named too.
    """
    if e.source is not None:
        return e
    text = request.positions
    pos_file = (
        text if "position" in e.items and request.select is None and text and Path(text).is_file() else None
    )
    load_file = loads if "load" in e.items and loads and Path(loads).is_file() else None
    if pos_file and load_file:
        return InputError(
            f"{e.detail} (load {e.items['load']} from {load_file})", source=pos_file, items=e.items
        )
    if pos_file or load_file:
        return e.with_source(pos_file or load_file)
    return e


def simulate_campaign(
    out_dir: str | os.PathLike,
    request: SimulationRequest,
    *,
    camera: CameraSimOptions | None = None,
    sensor: SensorSimOptions | None = None,
    progress: Callable[[int, int], None] | None = None,
    notify: Callable[[SimulationPlan, Backend], None] | None = None,
) -> SimSummary | SensorSimSummary:
    """Simulate a campaign of a test-bed robot: camera images or sensor recordings, as its
    test-bed says (the other options must not be given).

    Raises
    ------
    FieldError
        Options of the other instrument, or a wrong value (naming the request's field).
    InputError
        As :func:`simulate_camera_campaign` and :func:`simulate_sensor_campaign`.
    """
    _, tb, _, _ = _request_testbed(request)
    if tb.instrument == SENSOR:
        if camera is not None:
            raise FieldError("camera", f"not used when simulating {request.robot}'s sensor recordings")
        return simulate_sensor_campaign(out_dir, request, sensor or SensorSimOptions())
    if sensor is not None:
        raise FieldError("sensor", f"not used when simulating {request.robot}'s camera images")
    summary, _ = simulate_camera_campaign(
        out_dir, request, camera or CameraSimOptions(), progress=progress, notify=notify
    )
    return summary


def _camera_robot(request: SimulationRequest, options: CameraSimOptions, kind: RobotKind, tb: TestBed):
    """The virtual robot and where the loads act (FieldError naming params, rotations, load point)."""
    lp = options.load_point_mm if options.load_point_mm is not None else tb.load_point_mm
    if tb.rotations and options.rot_stiffness_nmm_per_rad is not None:
        raise FieldError(
            "rot_stiffness_nmm_per_rad", f"{tb.name}'s rotations come from its joints; leave it out"
        )
    if options.rot_stiffness_nmm_per_rad is not None and options.rot_stiffness_nmm_per_rad <= 0:
        raise FieldError("rot_stiffness_nmm_per_rad", "must be positive")
    if not tb.rotations and options.rot_stiffness_nmm_per_rad is None and any(lp):
        raise FieldError(
            ("load_point_mm", "rot_stiffness_nmm_per_rad"),
            "{load_point_mm} needs {rot_stiffness_nmm_per_rad} (a 3x3 field has no rotation)",
        )
    try:
        return tb.robot(float_params(request.params, kind.name)), tuple(float(v) for v in lp)
    except FieldError:
        raise
    except (TypeError, ValueError) as e:
        raise FieldError("params", str(e)) from None


def simulate_camera_campaign(
    out_dir: str | os.PathLike,
    request: SimulationRequest,
    options: CameraSimOptions,
    *,
    progress: Callable[[int, int], None] | None = None,
    notify: Callable[[SimulationPlan, Backend], None] | None = None,
) -> tuple[SimSummary, SimulationPlan]:
    """A vision campaign of a test-bed robot: calibration views, images and truth.

    Parameters
    ----------
    out_dir : path-like
        New or empty (or a previous simulation, with ``request.force``).
    request : SimulationRequest
    options : CameraSimOptions
    progress : callable, optional
        ``progress(done, total)`` after each rendered image.
    notify : callable, optional
        ``notify(plan, backend)`` once the images are planned, before they are rendered.

    Returns
    -------
    summary : SimSummary
    plan : SimulationPlan

    Raises
    ------
    FieldError
        A wrong value, naming the request's or the options' field.
    InputError
        A file that cannot be read; a position the robot does not reach or a board that
        leaves the image (naming the positions' or loads' file when they come from one);
        a disk too small.
    """
    kind, tb, P, own = _request_testbed(request)
    check_output_dir(out_dir, request.force)
    P = _positions(request, kind, tb) if P is None else P
    try:
        load_cases = load_design(options.loads, G_REFERENCE_PAPER)
    except InputError:
        raise
    except ValueError as e:
        raise FieldError("loads", str(e), value=options.loads) from None
    cam = load_camera(options.camera_file) if options.camera_file is not None else None
    robot, lp = _camera_robot(request, options, kind, tb)
    cfg = vision_config(
        robot, P, load_cases, cam, rot_stiffness_nmm_per_rad=options.rot_stiffness_nmm_per_rad,
        load_point_mm=lp, repeatability_mm=options.repeatability_mm, jitter_mm=options.jitter_mm,
        noise=options.noise, blur_px=options.blur_px, clutter=options.clutter, colour=options.colour,
        repeats=request.repeats, seed=request.seed, image_format=options.image_format,
        jpeg_quality=options.jpeg_quality, name=request.name or tb.campaign_name,
        calibration_views=options.calibration_views, cameras=options.cameras,
        camera_angle_deg=options.camera_angle_deg, scene=None if tb.scene is None else tb.scene(cam),
    )  # fmt: skip
    setup: tuple[tuple[str, str], ...] = ()
    if own is not None:
        cfg, loads_text, warnings = _own_loads(cfg, options.loads)
        where = own.positions_text if request.positions is None else request.positions
        where += f"; positions {request.select} of them" if request.select else ""
        setup = (("positions", where), ("loads", loads_text))
    render = not options.truth_only
    try:
        sim = plan_simulation(cfg, out_dir, render_images=render, advice=_DISK_ADVICE)
    except InputError as e:
        raise _naming_files(e, request, options.loads) from None
    workers = options.workers or local_workers()
    if notify is not None:
        notify(sim, Backend(workers, options.dask))
    summary = write_campaign(
        out_dir, cfg, workers=workers, force=request.force, render_images=render, progress=progress,
        command=request.command, plan=sim.plan, dask=options.dask,
    )  # fmt: skip
    if own is not None:
        summary = replace(summary, setup=setup, notes=own.notes, warnings=warnings)
    return summary, sim


#: A robot of one's own on the test-bed: the largest displacement of its tool point (mm) under
#: a preset's loads (``paper9``) outside this range has the preset scaled to about
#: :data:`OWN_TARGET_DISPLACEMENT_MM` (a load file's forces are kept, with a warning). Measured
#: (the shipped hexapod's geometry on legs of 375-600 N/mm, 6 positions x 9 loads x 2 repeats,
#: seed 0; docs/simulation.md; benchmarks/results/own_legs.md on another geometry, three seeds):
#: paper9 moves the tool point by 0.019 mm at most and the
#: campaign recovers K6 within 6.5 % and the legs within 11.5 %; its forces x 10 (0.22 mm) within
#: 0.58 % and 1.0 %; x 50 (0.95 mm) within 0.13 % and 0.2 %: the legs' error goes as about
#: 0.2 % mm / displacement, 0.4 % at the lower bound.
OWN_DISPLACEMENT_RANGE_MM = (0.5, LARGE_DISPLACEMENT_MM)
#: What a scaled preset aims at, mm: the test-bed's own robots' (the reference study's Delta, the
#: test-bed hexapod: about 1 mm).
OWN_TARGET_DISPLACEMENT_MM = 1.0


def _largest_displacement(cfg: SimConfig) -> float | None:
    """The largest displacement of the tool point (mm) over the positions and load cases (None:
    the field fails at a position, which the plan names)."""
    try:
        K = cfg.robot.stiffness(cfg.positions, cfg.orientations)
    except ValueError:
        return None
    K3 = translational_stiffness(K, cfg.robot.load_point_mm)
    F = np.array([ld.force for ld in cfg.loads], dtype=float)
    u = np.linalg.solve(K3[:, None], np.broadcast_to(F[None, :, :, None], (len(K3), *F.shape, 1)))
    return float(np.max(np.linalg.norm(u[..., 0], axis=-1)))


def _round_factor(x: float) -> float:
    """``x`` rounded to the nearest of 1, 2 and 5 times a power of ten, in log scale (48 -> 50, 3 -> 2)."""
    k = np.floor(np.log10(x))
    candidates = np.array([1.0, 2.0, 5.0, 10.0]) * 10.0**k
    return float(candidates[np.argmin(np.abs(np.log(candidates / x)))])


def _own_loads(cfg: SimConfig, loads: str) -> tuple[SimConfig, str, tuple[str, ...]]:
    """A robot of one's own: its loads scaled as :data:`OWN_DISPLACEMENT_RANGE_MM` says (a preset),
    in words for the summary, and the warnings (a load file's forces too small or too large)."""
    lp = cfg.robot.load_point_mm
    at = (
        f"hung at ({', '.join(f'{v:g}' for v in lp)}) mm from the tool point"
        if any(lp)
        else "at the tool point"
    )
    u = _largest_displacement(cfg)
    lo, hi = OWN_DISPLACEMENT_RANGE_MM
    if u is None:
        return cfg, f"{loads}, {at}", ()
    if lo <= u <= hi:
        return cfg, f"{loads}, {at}; largest predicted displacement {u:.3g} mm", ()
    if loads.strip().lower() not in PRESETS:
        why = "too small for the camera to measure well" if u < lo else "large for a linear model"
        return (
            cfg,
            f"{loads}, {at}; largest predicted displacement {u:.3g} mm",
            (
                f"the loads of {loads} move the tool point by {u:.3g} mm at most, {why} (the test-bed's "
                f"robots move by about {OWN_TARGET_DISPLACEMENT_MM:g} mm; {lo:g} to {hi:g} mm measure well): "
                "scale its forces",
            ),
        )
    f = _round_factor(OWN_TARGET_DISPLACEMENT_MM / u)
    cfg = replace(cfg, loads=tuple(scaled_loads(cfg.loads, f)))
    masses = ", ".join(
        dict.fromkeys(ld.label.split(" kg")[0] + " kg" for ld in cfg.loads if " kg" in ld.label)
    )
    return (
        cfg,
        (
            f"{loads} x {f:g} ({masses}), {at}; largest predicted displacement {u * f:.3g} mm (x {f:g}: "
            f"{loads} alone gives {u:.3g} mm, outside the {lo:g} to {hi:g} mm measured well)"
        ),
        (),
    )


#: What a full disk's message suggests.
_DISK_ADVICE = "simulate fewer positions, load cases or repeats, or write JPEG images"


def simulate_sensor_campaign(
    out_dir: str | os.PathLike, request: SimulationRequest, options: SensorSimOptions
) -> SensorSimSummary:
    """A sensor campaign of a test-bed robot: displacement recordings of stepped loads, and truth.

    Raises
    ------
    FieldError
        A wrong value (``directions``, ``trace_format``, ``params``, ``positions``...).
    InputError
        A position the robot does not reach (naming the positions' file when it is one).
    """
    kind, tb = testbed(request.robot)
    check_output_dir(out_dir, request.force)
    P = _positions(request, kind, tb)
    try:
        model = tb.robot(request.params)
    except FieldError:
        raise
    except (TypeError, ValueError) as e:
        raise FieldError("params", str(e)) from None
    dirs = tuple(d.strip() for d in options.directions.split(",") if d.strip())
    fmt = options.trace_format.strip().lower()
    if fmt not in ("csv", "tdms", "mat"):
        raise FieldError("trace_format", f"{options.trace_format!r}: expected csv, tdms or mat")
    try:
        return write_sensor_campaign(
            out_dir, model, P, directions=dirs, repeats=request.repeats, seed=request.seed, fmt=fmt,
            force=request.force, name=request.name or tb.campaign_name,
            command=request.command,
        )  # fmt: skip
    except FieldError:
        raise
    except InputError as e:
        raise _naming_files(e, request) from None
