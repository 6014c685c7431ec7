"""``stiffmap simulate``: write a virtual campaign (camera images, or sensor recordings) with its truth.

Parses the options into a :class:`~stiffmap.campaign.simulate.SimulationRequest` and the
options of the robot's instrument (:class:`~stiffmap.campaign.simulate.CameraSimOptions` or
:class:`~stiffmap.campaign.simulate.SensorSimOptions`), calls
:func:`stiffmap.campaign.simulate.simulate_campaign` and prints. The test-bed robots and what
measures each are the robot kinds' registry's (:mod:`stiffmap.kinds`).
"""

from __future__ import annotations

import shlex
import sys
import time
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path

import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from ..campaign.simulate import (
    CAMERA,
    OWN_DISPLACEMENT_RANGE_MM,
    OWN_TARGET_DISPLACEMENT_MM,
    SENSOR,
    CameraSimOptions,
    SensorSimOptions,
    SimulationRequest,
    simulate_campaign,
    testbed,
    testbed_robots,
)
from ..campaign.simulated import SimSummary
from ..campaign.simulated_sensor import SensorSimSummary
from ..errors import InputError
from ..kinds import (
    CONFIGS_OPTION,
    DEFAULT_TESTBED,
    ROBOT_KINDS,
    command_names,
    description_from_command,
    kind_of_file,
    params_from_text,
)
from ..parallel import Backend
from ..sim.plan import SimulationPlan
from ..sim.testbed import DEFAULT_CALIBRATION_VIEWS
from .common import (
    dask_option,
    err,
    fmt,
    note,
    options_named,
    print_json,
    print_summary,
    three_numbers,
    warn,
)
from .model import _BASE_HELP, _LINKS_HELP, _OFFSET_HELP, _PACKAGE_PATH_HELP, _TIP_HELP, _XACRO_ARG_HELP


class ImageFormat(StrEnum):
    png = "png"
    jpeg = "jpeg"


#: Options of one instrument only (parameter name -> option), refused with the other.
_CAMERA_ONLY = {
    "loads": "--loads",
    "camera_file": "--camera",
    "image_format": "--format",
    "jpeg_quality": "--jpeg-quality",
    "colour": "--colour",
    "clutter": "--clutter",
    "noise": "--noise/--no-noise",
    "blur_px": "--blur-px",
    "repeatability_mm": "--repeatability-mm",
    "jitter_mm": "--jitter-mm",
    "rot_stiffness": "--rot-stiffness-nmm-per-rad",
    "load_point": "--load-point-mm",
    "truth_only": "--truth-only",
    "workers": "--workers",
    "dask": "--dask",
    "calibration_views": "--calibration-views",
    "true_camera": "--true-camera",
    "cameras": "--cameras",
    "camera_angle_deg": "--camera-angle-deg",
}
_SENSOR_ONLY = {"directions": "--directions", "trace_format": "--trace-format"}
#: The library's fields as this command's options.
_OPTION_NAMES = {
    "robot": "--robot",
    "positions": "--positions",
    "select": "--select",
    "params": "--param:",
    "loads": "--loads",
    "rot_stiffness_nmm_per_rad": "--rot-stiffness-nmm-per-rad",
    "load_point_mm": "--load-point-mm",
    "directions": "--directions",
    "trace_format": "--trace-format",
}


def _given(ctx: typer.Context, name: str) -> bool:
    """The option was on the command line (click's ParameterSource.COMMANDLINE, by name)."""
    return getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"


def _refuse_options_of_the_other_instrument(ctx: typer.Context, robot: str, instrument: str) -> None:
    """An option given for the other instrument is a mistake, not something to ignore."""
    other = _CAMERA_ONLY if instrument == SENSOR else _SENSOR_ONLY
    given = [opt for name, opt in other.items() if _given(ctx, name)]
    if given:
        what = f"the {robot}'s sensor traces" if instrument == SENSOR else f"the {robot}'s camera images"
        raise InputError(
            f"{', '.join(given)}: not used when simulating {what} (--robot {robot}); "
            "leave out, or choose the other --robot"
        )


def _calibration_views(ctx: typer.Context, n: int, true_camera: bool) -> int:
    """The number of calibration views of ``--calibration-views`` and ``--true-camera``."""
    if true_camera:
        if _given(ctx, "calibration_views") and n:
            raise InputError(
                f"--true-camera and --calibration-views {n}: choose one (--true-camera means no "
                "calibration views)"
            )
        return 0
    if 0 < n < 3:
        raise InputError(
            f"--calibration-views {n}: a calibration needs at least 3 views (20 is what a careful "
            "lab takes); 0 gives the true camera"
        )
    return n


def _load_point(text: str | None):
    """``--load-point-mm`` as (x, y, z), mm (None: the test-bed's)."""
    if text is None:
        return None
    lp = three_numbers(text)
    if lp is None:
        raise InputError(f"--load-point-mm {text!r}: expected x,y,z in mm")
    return lp


# The options of `simulate` (declared here so that the command's signature reads at once).
_OPT_OUT_DIR = typer.Argument(..., help="Directory to create (must be new or empty).", show_default=False)
_OPT_ROBOT = typer.Option(
    DEFAULT_TESTBED,
    "--robot",
    help="Test-bed robot giving the true stiffness field: "
    + ", ".join(testbed_robots())
    + ". delta: the Delta-type robot; 3prr: sensor traces of the planar 3PRR; arm6: stiffmap's "
    "six-joint arm from its URDF, tool pointing down, loads hung from a bracket at (150, 100, "
    "-150) mm from the measured point; its joint stiffnesses k1..k6 are fitted by 'stiffmap run'. "
    "Or a robot of your own, its description ROBOT.urdf or .xacro, with --tip, --configs, --param "
    "k_theta=... (and --base, --xacro-arg, --package-path, --links as 'stiffmap model urdf'); or "
    "a legs TOML, ROBOT.toml (dim = 6: a hexapod, a 3-RPS, the loads hung 100 mm below the tool "
    "point as for hexapod; dim = 3: a translational robot, a 3x3 field), with --param k_leg1=... "
    "overriding its [params]; without --positions, a 3 x 3 x 2 grid about its home position.",
)
_OPT_POSITIONS = typer.Option(
    None,
    "--positions",
    help="Delta: paper48 (default: the reference study's 48 positions), a CSV file with columns "
    "x, y, z (mm), or 'x,y,z;x,y,z'. 3PRR: points22 (default), a CSV file with x, y, or 'x,y;x,y'. "
    "arm6: arm20 (default: 20 positions in front of the arm), a CSV file or a list. hexapod: 18 "
    "level positions (default), a list, or a CSV file with x, y, z and optionally roll_deg, pitch_deg, "
    "yaw_deg (degrees): the platform turned; the same for a dim = 6 legs TOML of your own, whose "
    "default is a 3 x 3 x 2 grid about its home position, spacing 0.12 of its size (a platform of "
    "lower mobility, a 3-RPS: in the coordinates it controls, roll and pitch -8, 0, 8 deg and z "
    "half a step either side, x, y and yaw solved).",
    show_default=False,
)
_OPT_SELECT = typer.Option(
    None, "--select", help="Keep only these positions, 1-based, e.g. 1,22,48.", show_default=False
)
_OPT_LOADS = typer.Option(
    "paper9",
    "--loads",
    help="paper9 (0.5, 0.2, 0.1 kg along +y, -x, -z) or a CSV file with fx, fy, fz (N). For a robot "
    "of your own (--robot FILE), paper9's masses are scaled (by 1, 2 or 5 times a power of ten, "
    f"towards {OWN_TARGET_DISPLACEMENT_MM:g} mm) when they would move the tool point by less than "
    f"{OWN_DISPLACEMENT_RANGE_MM[0]:g} or more than {OWN_DISPLACEMENT_RANGE_MM[1]:g} mm; a CSV "
    "file's forces are used as given (a warning when outside that range).",
)
_OPT_REPEATS = typer.Option(
    3,
    "--repeats",
    min=1,
    help="Unloaded/loaded image pairs per load case (3PRR: recordings per point/axis).",
)
_OPT_DIRECTIONS = typer.Option(
    "x,y", "--directions", help="3PRR: load and measurement axes at each point (x, y or x,y)."
)
_OPT_TRACE_FORMAT = typer.Option("csv", "--trace-format", help="3PRR: recording format (csv, tdms, mat).")
_OPT_SEED = typer.Option(0, "--seed", min=0, help="Seed of every random draw (same seed, same files).")
_OPT_WORKERS = typer.Option(
    0, "--workers", min=0, help="Processes rendering images (0: one per available CPU)."
)
_OPT_FORCE = typer.Option(
    False, "--force", help="Overwrite a previous simulation in OUT_DIR (never a real campaign)."
)
_OPT_IMAGE_FORMAT = typer.Option(ImageFormat.png, "--format", help="Image format.")
_OPT_JPEG_QUALITY = typer.Option(95, "--jpeg-quality", min=1, max=100, help="JPEG quality.")
_OPT_COLOUR = typer.Option(False, "--colour", help="A Bayer colour camera (demosaiced BGR images).")
_OPT_CLUTTER = typer.Option(False, "--clutter", help="A cluttered background instead of a plain one.")
_OPT_NOISE = typer.Option(True, "--noise/--no-noise", help="Sensor noise and vignetting.")
_OPT_BLUR_PX = typer.Option(0.8, "--blur-px", min=0.0, help="Optics blur (Gaussian sigma), px.")
_OPT_REPEATABILITY_MM = typer.Option(
    0.02, "--repeatability-mm", min=0.0, help="Robot position repeatability, 1 sigma per axis, mm."
)
_OPT_JITTER_MM = typer.Option(
    0.001, "--jitter-mm", min=0.0, help="Per-image position jitter (settling), 1 sigma per axis, mm."
)
_OPT_ROT_STIFFNESS = typer.Option(
    None,
    "--rot-stiffness-nmm-per-rad",
    min=0.0,
    help="Give the platform this rotational stiffness (N*mm/rad): a 6x6 field at the tool point.",
    show_default=False,
)
_OPT_LOAD_POINT = typer.Option(
    None,
    "--load-point-mm",
    help="Where the loads act, in the tool frame, mm (with a 6x6 field; default 0,0,0, "
    "150,100,-150 for arm6, 0,0,-100 for hexapod and a dim = 6 legs TOML).",
    show_default=False,
)
_OPT_PARAM = typer.Option(
    [], "--param", help="Robot model parameter NAME=VALUE (repeatable), e.g. k_theta=3e5."
)
_OPT_CAMERA_FILE = typer.Option(
    None, "--camera", help="camera.json to simulate instead of the reference camera.", show_default=False
)
_OPT_CALIBRATION_VIEWS = typer.Option(
    DEFAULT_CALIBRATION_VIEWS,
    "--calibration-views",
    min=0,
    help="Views of an 11x8 calibration board (25 mm squares) rendered first, at the poses a "
    "careful user takes, from which camera.json is calibrated as `stiffmap calibrate` does "
    "(0: the true camera; else at least 3).",
)
_OPT_TRUE_CAMERA = typer.Option(
    False,
    "--true-camera",
    help="Give the campaign the true camera in camera.json (no calibration views; = --calibration-views 0).",
)
_OPT_TRUTH_ONLY = typer.Option(
    False,
    "--truth-only",
    help="Write the spec, camera and truth but no images (fast; for tests). Nothing to "
    "calibrate from: camera.json is the true camera.",
)
_OPT_CAMERAS = typer.Option(
    1,
    "--cameras",
    min=1,
    max=8,
    help="Cameras looking at the robot: 2 or more make a rig (rig.json), about --camera-angle-deg "
    "apart about the vertical, each image a set of one image per camera.",
)
_OPT_CAMERA_ANGLE_DEG = typer.Option(
    60.0,
    "--camera-angle-deg",
    min=1.0,
    max=120.0,
    help="Angle between the first and last camera, degrees.",
)
_OPT_NAME = typer.Option(
    None, "--name", help="Campaign name (default: virtual test-bed).", show_default=False
)
_OPT_AS_JSON = typer.Option(False, "--json", help="Print a JSON summary instead of a table.")
#: The options of a robot of one's own (--robot FILE), as 'stiffmap model urdf' says them.
_OWN = "--robot FILE.urdf or .xacro: "
_OPT_TIP = typer.Option(None, "--tip", help=_OWN + _TIP_HELP.removeprefix("urdf: "), show_default=False)
_OPT_TIP_OFFSET = typer.Option(None, "--tip-offset-mm", help=_OWN + _OFFSET_HELP.removeprefix("urdf: "))
_OPT_BASE = typer.Option(None, "--base", help=_OWN + _BASE_HELP.removeprefix("urdf: "))
_OPT_XACRO_ARG = typer.Option(None, "--xacro-arg", help=_OWN + _XACRO_ARG_HELP.removeprefix("urdf: "))
_OPT_PACKAGE_PATH = typer.Option(
    None, "--package-path", help=_OWN + _PACKAGE_PATH_HELP.removeprefix("urdf: ")
)
_OPT_LINKS = typer.Option(None, "--links", help=_OWN + _LINKS_HELP.removeprefix("urdf: "))
_OPT_CONFIGS = typer.Option(
    None,
    "--configs",
    help=_OWN + "CSV of joint configurations (columns named after the joints, or q1_deg..qn_deg; mm "
    "for a prismatic joint): the positions, their measured points.",
)


def _own_robot(robot: str, param, options: dict, configs):
    """``--robot FILE``: the description of a robot of the user's own (None for a test-bed robot),
    and the names of the library's fields as this command's options."""
    kind = kind_of_file(robot) if robot not in testbed_robots() else None
    given = {k: v for k, v in options.items() if v is not None}
    if configs is not None:
        given[CONFIGS_OPTION] = configs
    if kind is None:
        if given:
            raise InputError(
                f"{', '.join(given)}: for a robot of your own ({_own_files()}), not the test-bed's {robot}"
            )
        return None, _OPTION_NAMES
    if not Path(robot).is_file():
        raise InputError(
            f"--robot {robot}: no such file (a test-bed robot is one of {', '.join(testbed_robots())})"
        )
    d = description_from_command(
        kind.name, robot, param or [], options, configs=configs, command="simulate", configs_required=False
    )
    return d, {**_OPTION_NAMES, **command_names(kind), "file": "--robot"}


def _own_files() -> str:
    """The files ``--robot`` takes as a robot of one's own (``--robot FILE.urdf, .xacro or .toml``)."""
    suffixes = [x for k in ROBOT_KINDS.values() if k.testbed and k.testbed.own for x in k.file_suffixes]
    listed = ", ".join(suffixes[:-1]) + (" or " if len(suffixes) > 1 else "") + suffixes[-1]
    return f"--robot FILE{listed}"


def _instrument(robot: str) -> str:
    """What measures test-bed robot ``robot`` (InputError naming --robot when there is none)."""
    with options_named(_OPTION_NAMES):
        return testbed(robot)[1].instrument


def _own_options(tip, tip_offset, base, xacro_arg, package_path, links) -> dict:
    """The options of a robot of one's own, by their names (None: not given)."""
    return {
        "--tip": tip,
        "--tip-offset-mm": tip_offset,
        "--base": base,
        "--xacro-arg": xacro_arg or None,
        "--package-path": package_path or None,
        "--links": None if links is None else str(links),
    }


def simulate(
    ctx: typer.Context,
    out_dir: Path = _OPT_OUT_DIR,
    robot: str = _OPT_ROBOT,
    positions: str = _OPT_POSITIONS,
    select: str = _OPT_SELECT,
    loads: str = _OPT_LOADS,
    repeats: int = _OPT_REPEATS,
    directions: str = _OPT_DIRECTIONS,
    trace_format: str = _OPT_TRACE_FORMAT,
    seed: int = _OPT_SEED,
    workers: int = _OPT_WORKERS,
    dask: str | None = dask_option("Render the images"),
    force: bool = _OPT_FORCE,
    image_format: ImageFormat = _OPT_IMAGE_FORMAT,
    jpeg_quality: int = _OPT_JPEG_QUALITY,
    colour: bool = _OPT_COLOUR,
    clutter: bool = _OPT_CLUTTER,
    noise: bool = _OPT_NOISE,
    blur_px: float = _OPT_BLUR_PX,
    repeatability_mm: float = _OPT_REPEATABILITY_MM,
    jitter_mm: float = _OPT_JITTER_MM,
    rot_stiffness: float = _OPT_ROT_STIFFNESS,
    load_point: str = _OPT_LOAD_POINT,
    param: list[str] = _OPT_PARAM,
    camera_file: Path = _OPT_CAMERA_FILE,
    calibration_views: int = _OPT_CALIBRATION_VIEWS,
    true_camera: bool = _OPT_TRUE_CAMERA,
    truth_only: bool = _OPT_TRUTH_ONLY,
    cameras: int = _OPT_CAMERAS,
    camera_angle_deg: float = _OPT_CAMERA_ANGLE_DEG,
    name: str = _OPT_NAME,
    tip: str = _OPT_TIP,
    tip_offset: str = _OPT_TIP_OFFSET,
    base: str = _OPT_BASE,
    xacro_arg: list[str] = _OPT_XACRO_ARG,
    package_path: list[str] = _OPT_PACKAGE_PATH,
    links: Path = _OPT_LINKS,
    configs: Path = _OPT_CONFIGS,
    as_json: bool = _OPT_AS_JSON,
) -> None:
    """Simulate a vision campaign of a robot with known stiffness, seen by a known camera.

    Writes OUT_DIR/calibration/ (views of a calibration board) and camera.json (the camera
    calibrated from them, as a lab would), campaign.toml, images/ (an unloaded and a loaded
    image per position, load case and repeat) and the ground truth truth.json (true K at
    every position, every image's poses, the true camera beside the calibrated one) with
    truth_corners.json.gz (true corner pixels). The same --seed gives byte-identical files,
    whatever --workers. With --cameras N (2 or more), a rig of N cameras: rig.json calibrated
    from views of the board seen by the cameras together, and one image per camera in each
    image set (campaign.toml's [cameras]).
    """
    own = _own_options(tip, tip_offset, base, xacro_arg, package_path, links)
    description, names = _own_robot(robot, param, own, configs)
    instrument = CAMERA if description is not None else _instrument(robot)
    _refuse_options_of_the_other_instrument(ctx, robot, instrument)
    command = "stiffmap " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv else ""
    with options_named(names):
        request = SimulationRequest(
            robot=robot, positions=positions, select=select, repeats=repeats, seed=seed,
            params={} if description else params_from_text(param), name=name, force=force, command=command,
            description=description,
        )  # fmt: skip
    if instrument == SENSOR:
        with options_named(names):
            s = simulate_campaign(out_dir, request, sensor=SensorSimOptions(directions, trace_format))
        _print_sensor_summary(s, request.seed, as_json)
        return
    options = CameraSimOptions(
        loads=loads, camera_file=camera_file, image_format=image_format.value, jpeg_quality=jpeg_quality,
        colour=colour, clutter=clutter, noise=noise, blur_px=blur_px, repeatability_mm=repeatability_mm,
        jitter_mm=jitter_mm, rot_stiffness_nmm_per_rad=rot_stiffness, load_point_mm=_load_point(load_point),
        calibration_views=_calibration_views(ctx, calibration_views, true_camera), cameras=cameras,
        camera_angle_deg=camera_angle_deg, truth_only=truth_only, workers=workers, dask=dask,
    )  # fmt: skip
    with _rendering(out_dir, show=not (as_json or truth_only)) as view, options_named(names):
        summary = simulate_campaign(
            out_dir, request, camera=options, progress=view.progress, notify=view.notify
        )
    _print_vision_summary(summary, view.sim, as_json)


class _Rendering:
    """The command's view of a simulation: the plan's announcement and a progress bar on stderr."""

    def __init__(self, out_dir: Path, show: bool) -> None:
        self.out_dir, self.show = out_dir, show
        self.sim: SimulationPlan | None = None
        self.bar: Progress | None = None
        self.t0 = time.perf_counter()

    def notify(self, sim: SimulationPlan, backend: Backend) -> None:
        """The plan is made: say what will be rendered where, start the bar."""
        self.sim = sim
        if not self.show:
            return
        cfg = sim.config
        views = f" + {sim.n_calibration_views} calibration views" if sim.n_calibration_views else ""
        err.print(
            f"simulating {len(cfg.positions)} position(s) x {len(cfg.loads)} load case(s) x {cfg.repeats} "
            f"repeat(s): {sim.n_images} images{views} (~{sim.bytes_needed / 1e9:.2f} GB) on "
            f"{backend.describe()} -> {self.out_dir}",
            highlight=False,
        )
        self.bar = Progress(
            TextColumn("rendering"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[rate]}"),
            TimeElapsedColumn(),
            TextColumn("left"),
            TimeRemainingColumn(),
            console=err,
        )
        self.bar.start()
        self.task = self.bar.add_task("images", total=(sim.n_images + sim.n_calibration_views) or 1, rate="")
        self.t0 = time.perf_counter()

    def progress(self, done: int, total: int) -> None:
        if self.bar is None:
            return
        dt = time.perf_counter() - self.t0
        rate = f"{done / dt:.2f} images/s" if done and dt > 0 else ""
        self.bar.update(self.task, completed=done, total=total or 1, rate=rate)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


@contextmanager
def _rendering(out_dir: Path, show: bool):
    view = _Rendering(out_dir, show)
    try:
        yield view
    finally:
        view.close()


def _print_vision_summary(summary: SimSummary, sim: SimulationPlan, as_json: bool) -> None:
    """The simulated vision campaign: a table, or one JSON object (its notes and warnings first)."""
    for text in summary.notes:
        note(text)
    for text in summary.warnings:
        warn(text)
    cfg = sim.config
    vr = cfg.robot
    lo, hi = summary.principal_range
    cal_dir = ", calibration/" if summary.calibration.calibrated else ""
    views = f" + {summary.calibration.n_views} calibration views" if summary.calibration.calibrated else ""
    if as_json:
        print_json(
            {
                "out_dir": str(summary.out_dir),
                "positions": summary.n_positions,
                "load_cases": summary.n_loads,
                "repeats": summary.repeats,
                "images": summary.n_images,
                "format": cfg.image_format,
                "bytes": summary.bytes_written,
                "seconds": summary.seconds,
                "seed": cfg.seed,
                "robot": vr.model,
                "params": vr.params,
                "field": "6x6" if sim.plan.K.shape[-1] == 6 else "3x3",
                "principal_stiffness_range": [lo, hi],
                "calibration": {
                    **summary.calibration.to_dict(),
                    "seconds": summary.calibration_seconds,
                },
                "files": list(summary.files),
                **({"setup": dict(summary.setup)} if summary.setup else {}),
            }
        )
        return
    print_summary(
        f"simulated campaign in {summary.out_dir}",
        [
            (
                "images",
                f"{summary.n_images} {cfg.image_format}{views} ({summary.bytes_written / 1e6:.1f} MB)",
            ),
            ("positions x loads x repeats", f"{summary.n_positions} x {summary.n_loads} x {summary.repeats}"),
            ("robot", f"{vr.model} ({', '.join(f'{k}={v:g}' for k, v in vr.params.items())})"),
            *summary.setup,
            ("true principal stiffnesses", f"{fmt(lo, 4)} to {fmt(hi, 4)} N/mm"),
            *_calibration_rows(summary),
            ("seed", str(cfg.seed)),
            ("time", f"{summary.seconds:.1f} s"),
            ("files", ", ".join(summary.files) + ", images/" + cal_dir),
        ],
    )


def _calibration_rows(summary: SimSummary) -> list[tuple[str, str]]:
    """The summary's rows on camera.json: calibrated (views, RMS, errors against the truth) or true."""
    c = summary.calibration
    if not c.calibrated:
        if "rig.json" in summary.files:
            return [("rig.json", f"the true cameras: {c.note}")]
        return [("camera.json", f"the true camera: {c.note}")]
    if "rig.json" in summary.files:
        return [
            (
                "rig.json",
                f"calibrated (stiffmap calibrate-rig) from {c.n_views} views, each camera using "
                f"{c.n_used} or more, RMS {c.rms_px:.4f} px ({summary.calibration_seconds:.1f} s)",
            ),
            ("first camera vs true", c.errors_text()),
        ]
    return [
        (
            "camera.json",
            f"calibrated from {c.n_used} of {c.n_views} views, RMS {c.rms_px:.4f} px "
            f"({summary.calibration_seconds:.1f} s)",
        ),
        ("calibration vs true camera", c.errors_text()),
    ]


def _print_sensor_summary(s: SensorSimSummary, seed: int, as_json: bool) -> None:
    """The simulated sensor campaign: a table, or one JSON object."""
    lo, hi = s.static_error_range_mm
    params, fmt_name = s.params, s.format
    if as_json:
        print_json(
            {
                "out_dir": str(s.out_dir),
                "kind": "sensor",
                "points": s.n_points,
                "directions": list(s.directions),
                "repeats": s.repeats,
                "recordings": s.n_recordings,
                "format": fmt_name,
                "bytes": s.bytes_written,
                "seconds": s.seconds,
                "seed": seed,
                "robot": s.robot,
                "params": params,
                "static_error_range_mm": [lo, hi],
                "files": ["campaign.toml", "truth.json", "recordings/"],
            }
        )
        return
    print_summary(
        f"simulated sensor campaign in {s.out_dir}",
        [
            ("recordings", f"{s.n_recordings} {fmt_name} ({s.bytes_written / 1e6:.1f} MB)"),
            ("points x axes x repeats", f"{s.n_points} x {len(s.directions)} x {s.repeats}"),
            ("robot", f"{s.robot} ({', '.join(f'{k}={v:g}' for k, v in params.items())})"),
            ("true static errors at 50 kgf", f"{fmt(lo, 4)} to {fmt(hi, 4)} mm"),
            ("seed", str(seed)),
            ("time", f"{s.seconds:.1f} s"),
            ("files", "campaign.toml, truth.json, recordings/ (+ index.csv); run: stiffmap run DIR"),
        ],
    )


def register(app: typer.Typer) -> None:
    app.command("simulate")(simulate)
