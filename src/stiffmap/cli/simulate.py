"""``stiffmap simulate``: write a virtual campaign (vision, or sensor for the 3PRR) with its ground truth.

The simulation is planned by :mod:`stiffmap.sim.plan` and written by
:mod:`stiffmap.campaign.simulated` (vision) or :mod:`stiffmap.campaign.simulated_sensor`
(3PRR); positions come from :mod:`stiffmap.models.presets`, loads from :mod:`stiffmap.loads`.
"""

from __future__ import annotations

import re
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

from ..camera import load_camera
from ..campaign.simulated import SimSummary, check_output_dir, write_campaign
from ..campaign.simulated_sensor import SensorSimSummary, write_sensor_campaign
from ..errors import InputError
from ..loads import load_design
from ..models import arm6
from ..models.presets import positions_from_text, select_positions
from ..models.prr3 import PRR3
from ..parallel import Backend, local_workers
from ..sim.plan import SimulationPlan, plan_simulation, vision_config
from ..sim.robot import arm6_robot, delta_robot
from ..sim.scene import arm_scene
from ..sim.testbed import DEFAULT_CALIBRATION_VIEWS
from ..units import G_REFERENCE_PAPER
from .common import (
    dask_option,
    err,
    float_values,
    fmt,
    from_option,
    parse_key_values,
    print_json,
    print_summary,
    three_numbers,
)


class RobotName(StrEnum):
    delta = "delta"
    prr3 = "3prr"
    arm6 = "arm6"


class ImageFormat(StrEnum):
    png = "png"
    jpeg = "jpeg"


#: Options of one kind of simulation only (parameter name -> option), refused with the other.
_VISION_ONLY = {
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
}
_SENSOR_ONLY = {"directions": "--directions", "trace_format": "--trace-format"}
#: What a full disk's message suggests.
_DISK_ADVICE = "use fewer --positions/--select/--repeats or --format jpeg"


def _calibration_views(ctx: typer.Context, n: int, true_camera: bool) -> int:
    """The number of calibration views of ``--calibration-views`` and ``--true-camera``."""
    if true_camera:
        if getattr(ctx.get_parameter_source("calibration_views"), "name", "") == "COMMANDLINE" and n:
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


def _refuse_options_of_the_other_robot(ctx: typer.Context, robot: RobotName) -> None:
    """An option given for the other kind of simulation is a mistake, not something to ignore."""
    other = _VISION_ONLY if robot is RobotName.prr3 else _SENSOR_ONLY

    def on_command_line(name: str) -> bool:  # click's ParameterSource.COMMANDLINE, by name
        return getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"

    given = [opt for name, opt in other.items() if on_command_line(name)]
    if given:
        what = "the 3PRR's sensor traces" if robot is RobotName.prr3 else f"the {robot.value}'s camera images"
        raise InputError(
            f"{', '.join(given)}: not used when simulating {what} (--robot {robot.value}); "
            "leave out, or choose the other --robot"
        )


def _positions(text: str, select: str | None, mech: str):
    """The positions of ``--positions`` (a preset, a CSV file or a list), those of ``--select`` only."""
    P = from_option("--positions", positions_from_text, text, mech)
    return from_option("--select", select_positions, P, select)


@contextmanager
def _naming_positions_file(text: str | None, select: str | None, loads: str | None = None):
    """A ``position N ...`` error about positions read from a CSV file names that file.

    The test-bed numbers the positions it refuses (unreachable, no stiffness); when they
    come from ``--positions FILE`` (all of them, no ``--select``), N is the file's Nth row.
    When the error is about a load case too (``load K``: a load that pushes the board out of
    view) and the loads come from ``--loads FILE``, that file is named as well.
    """
    try:
        yield
    except InputError as e:
        if e.source is not None:
            raise
        pos_file = None
        if select is None and e.detail.startswith("position ") and text and Path(text).is_file():
            pos_file = text
        m = re.search(r"\bload (\d+)\b", e.detail)
        load_file = loads if m and loads and Path(loads).is_file() else None
        if pos_file and load_file:
            k = m.group(1)
            raise InputError(f"{e.detail} (load {k} from {load_file})", source=pos_file) from None
        if pos_file or load_file:
            raise e.with_source(pos_file or load_file) from None
        raise


def _load_point(text: str):
    """``--load-point-mm`` as (x, y, z), mm."""
    lp = three_numbers(text)
    if lp is None:
        raise InputError(f"--load-point-mm {text!r}: expected x,y,z in mm")
    return lp


def _check_rotation_options(rot_stiffness: float | None, load_point) -> None:
    if rot_stiffness is not None:
        if rot_stiffness <= 0:
            raise InputError("--rot-stiffness-nmm-per-rad must be positive")
    elif any(load_point):
        raise InputError("--load-point-mm needs --rot-stiffness-nmm-per-rad (a 3x3 field has no rotation)")


def simulate(
    ctx: typer.Context,
    out_dir: Path = typer.Argument(
        ..., help="Directory to create (must be new or empty).", show_default=False
    ),
    robot: RobotName = typer.Option(
        RobotName.delta,
        "--robot",
        help="Robot model giving the true stiffness field: delta (the Delta-type robot), 3prr (sensor "
        "traces of the planar 3PRR) or arm6 (stiffmap's six-joint arm from its URDF, tool pointing down, "
        "loads hung from a bracket at (150, 100, -150) mm from the measured point; its joint "
        "stiffnesses k1..k6 are "
        "fitted by 'stiffmap run').",
    ),
    positions: str = typer.Option(
        None,
        "--positions",
        help="Delta: paper48 (default: the reference study's 48 positions), a CSV file with columns "
        "x, y, z (mm), or 'x,y,z;x,y,z'. 3PRR: points22 (default), a CSV file with x, y, or 'x,y;x,y'. "
        "arm6: arm20 (default: 20 positions in front of the arm), a CSV file or a list.",
        show_default=False,
    ),
    select: str = typer.Option(
        None, "--select", help="Keep only these positions, 1-based, e.g. 1,22,48.", show_default=False
    ),
    loads: str = typer.Option(
        "paper9",
        "--loads",
        help="paper9 (0.5, 0.2, 0.1 kg along +y, -x, -z) or a CSV file with fx, fy, fz (N).",
    ),
    repeats: int = typer.Option(
        3,
        "--repeats",
        min=1,
        help="Unloaded/loaded image pairs per load case (3PRR: recordings per point/axis).",
    ),
    directions: str = typer.Option(
        "x,y", "--directions", help="3PRR: load and measurement axes at each point (x, y or x,y)."
    ),
    trace_format: str = typer.Option(
        "csv", "--trace-format", help="3PRR: recording format (csv, tdms, mat)."
    ),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every random draw (same seed, same files)."),
    workers: int = typer.Option(
        0, "--workers", min=0, help="Processes rendering images (0: one per available CPU)."
    ),
    dask: str | None = dask_option("Render the images"),
    force: bool = typer.Option(
        False, "--force", help="Overwrite a previous simulation in OUT_DIR (never a real campaign)."
    ),
    image_format: ImageFormat = typer.Option(ImageFormat.png, "--format", help="Image format."),
    jpeg_quality: int = typer.Option(95, "--jpeg-quality", min=1, max=100, help="JPEG quality."),
    colour: bool = typer.Option(False, "--colour", help="A Bayer colour camera (demosaiced BGR images)."),
    clutter: bool = typer.Option(False, "--clutter", help="A cluttered background instead of a plain one."),
    noise: bool = typer.Option(True, "--noise/--no-noise", help="Sensor noise and vignetting."),
    blur_px: float = typer.Option(0.8, "--blur-px", min=0.0, help="Optics blur (Gaussian sigma), px."),
    repeatability_mm: float = typer.Option(
        0.02, "--repeatability-mm", min=0.0, help="Robot position repeatability, 1 sigma per axis, mm."
    ),
    jitter_mm: float = typer.Option(
        0.001, "--jitter-mm", min=0.0, help="Per-image position jitter (settling), 1 sigma per axis, mm."
    ),
    rot_stiffness: float = typer.Option(
        None,
        "--rot-stiffness-nmm-per-rad",
        min=0.0,
        help="Give the platform this rotational stiffness (N*mm/rad): a 6x6 field at the tool point.",
        show_default=False,
    ),
    load_point: str = typer.Option(
        None,
        "--load-point-mm",
        help="Where the loads act, in the tool frame, mm (with a 6x6 field; default 0,0,0, and "
        "150,100,-150 for arm6).",
        show_default=False,
    ),
    param: list[str] = typer.Option(
        [], "--param", help="Robot model parameter NAME=VALUE (repeatable), e.g. k_theta=3e5."
    ),
    camera_file: Path = typer.Option(
        None, "--camera", help="camera.json to simulate instead of the reference camera.", show_default=False
    ),
    calibration_views: int = typer.Option(
        DEFAULT_CALIBRATION_VIEWS,
        "--calibration-views",
        min=0,
        help="Views of an 11x8 calibration board (25 mm squares) rendered first, at the poses a "
        "careful user takes, from which camera.json is calibrated as `stiffmap calibrate` does "
        "(0: the true camera; else at least 3).",
    ),
    true_camera: bool = typer.Option(
        False,
        "--true-camera",
        help="Give the campaign the true camera in camera.json (no calibration views; "
        "= --calibration-views 0).",
    ),
    truth_only: bool = typer.Option(
        False,
        "--truth-only",
        help="Write the spec, camera and truth but no images (fast; for tests). Nothing to "
        "calibrate from: camera.json is the true camera.",
    ),
    cameras: int = typer.Option(
        1,
        "--cameras",
        min=1,
        max=8,
        help="Cameras looking at the robot: 2 or more make a rig (rig.json), about --camera-angle-deg "
        "apart about the vertical, each image a set of one image per camera.",
    ),
    camera_angle_deg: float = typer.Option(
        60.0,
        "--camera-angle-deg",
        min=1.0,
        max=120.0,
        help="Angle between the first and last camera, degrees.",
    ),
    name: str = typer.Option("virtual test-bed", "--name", help="Campaign name."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary instead of a table."),
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
    _refuse_options_of_the_other_robot(ctx, robot)
    check_output_dir(out_dir, force)
    command = "stiffmap " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv else ""
    if robot is RobotName.prr3:
        args = (positions, select, directions, repeats, seed, trace_format, force, param, name, command)
        _simulate_sensor(out_dir, *args, as_json)
        return
    arm = robot is RobotName.arm6
    P = _positions(positions or ("arm20" if arm else "paper48"), select, "urdf" if arm else "delta")
    load_cases = from_option("--loads", load_design, loads, G_REFERENCE_PAPER)
    cam = load_camera(camera_file) if camera_file is not None else None
    values = float_values(parse_key_values(param, "--param"), "--param")
    lp = _load_point(load_point or (",".join(f"{v:g}" for v in arm6.LOAD_POINT_MM) if arm else "0,0,0"))
    if arm:
        if rot_stiffness is not None:
            raise InputError(
                "--rot-stiffness-nmm-per-rad: arm6's rotations come from its joints; leave it out"
            )
        base = from_option("--param:", arm6_robot, values)
        scene = arm_scene(cam)
    else:
        base = from_option("--param:", delta_robot, values)
        _check_rotation_options(rot_stiffness, lp)
        scene = None
    n_views = _calibration_views(ctx, calibration_views, true_camera)
    cfg = vision_config(
        base, P, load_cases, cam, rot_stiffness_nmm_per_rad=rot_stiffness, load_point_mm=lp,
        repeatability_mm=repeatability_mm, jitter_mm=jitter_mm, noise=noise, blur_px=blur_px,
        clutter=clutter, colour=colour, repeats=repeats, seed=seed, image_format=image_format.value,
        jpeg_quality=jpeg_quality, name=name, calibration_views=n_views, cameras=cameras,
        camera_angle_deg=camera_angle_deg, scene=scene,
    )  # fmt: skip
    with _naming_positions_file(positions, select, loads):
        sim = plan_simulation(cfg, out_dir, render_images=not truth_only, advice=_DISK_ADVICE)
    n_workers = workers or local_workers()
    if not as_json:
        views = f" + {sim.n_calibration_views} calibration views" if sim.n_calibration_views else ""
        err.print(
            f"simulating {len(P)} position(s) x {len(load_cases)} load case(s) x {repeats} repeat(s): "
            f"{sim.n_images} images{views} (~{sim.bytes_needed / 1e9:.2f} GB) on "
            f"{Backend(n_workers, dask).describe()} -> {out_dir}",
            highlight=False,
        )
    with _rendering_progress(sim, show=not (as_json or truth_only)) as progress:
        summary = write_campaign(
            out_dir, cfg, workers=n_workers, force=force, render_images=not truth_only,
            progress=progress, command=command, plan=sim.plan, dask=dask,
        )  # fmt: skip
    _print_vision_summary(summary, sim, as_json)


@contextmanager
def _rendering_progress(sim: SimulationPlan, show: bool):
    """A progress bar of the rendered images on stderr, and its hook for write_campaign (None: no bar)."""
    if not show:
        yield None
        return
    t0 = time.perf_counter()
    with Progress(
        TextColumn("rendering"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=err,
    ) as bar:
        task = bar.add_task("images", total=(sim.n_images + sim.n_calibration_views) or 1, rate="")

        def progress(done: int, total: int) -> None:
            dt = time.perf_counter() - t0
            rate = f"{done / dt:.2f} images/s" if done and dt > 0 else ""
            bar.update(task, completed=done, total=total or 1, rate=rate)

        yield progress


def _print_vision_summary(summary: SimSummary, sim: SimulationPlan, as_json: bool) -> None:
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


def _simulate_sensor(
    out_dir: Path,
    positions: str | None,
    select: str | None,
    directions: str,
    repeats: int,
    seed: int,
    trace_format: str,
    force: bool,
    param: list[str],
    name: str,
    command: str,
    as_json: bool,
) -> None:
    """The 3PRR: LDV recordings of stepped loads, written as a sensor campaign."""
    P = _positions(positions or "points22", select, "3prr")
    model = from_option("--param:", _prr3, parse_key_values(param, "--param"))
    dirs = tuple(d.strip() for d in directions.split(",") if d.strip())
    trace_fmt = trace_format.strip().lower()
    if trace_fmt not in ("csv", "tdms", "mat"):
        raise InputError(f"--trace-format {trace_format!r}: expected csv, tdms or mat")
    with _naming_positions_file(positions, select):
        s = write_sensor_campaign(
            out_dir,
            model,
            P,
            directions=dirs,
            repeats=repeats,
            seed=seed,
            fmt=trace_fmt,
            force=force,
            name=name if name != "virtual test-bed" else "virtual test-bed (3PRR, LDV)",
            command=command,
        )
    _print_sensor_summary(s, model.params(), trace_fmt, seed, as_json)


def _prr3(given: dict[str, str]) -> PRR3:
    """The 3PRR with the parameters of ``--param`` (ValueError naming a bad one)."""
    return PRR3().with_params(**{k: float(v) for k, v in given.items()})


def _print_sensor_summary(s: SensorSimSummary, params: dict, fmt_name: str, seed: int, as_json: bool) -> None:
    lo, hi = s.static_error_range_mm
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
                "robot": "3prr",
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
            ("robot", f"3prr ({', '.join(f'{k}={v:g}' for k, v in params.items())})"),
            ("true static errors at 50 kgf", f"{fmt(lo, 4)} to {fmt(hi, 4)} mm"),
            ("seed", str(seed)),
            ("time", f"{s.seconds:.1f} s"),
            ("files", "campaign.toml, truth.json, recordings/ (+ index.csv); run: stiffmap run DIR"),
        ],
    )


def register(app: typer.Typer) -> None:
    app.command("simulate")(simulate)
