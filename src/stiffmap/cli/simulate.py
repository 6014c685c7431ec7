"""``stiffmap simulate``: write a virtual campaign (vision, or sensor for the 3PRR) with its ground truth."""

from __future__ import annotations

import os
import shlex
import shutil
import sys
import time
from enum import StrEnum
from pathlib import Path

import typer

from ..errors import InputError
from .common import err, float_values, fmt, parse_key_values, position_preset, print_json, print_summary


class RobotName(StrEnum):
    delta = "delta"
    prr3 = "3prr"


class ImageFormat(StrEnum):
    png = "png"
    jpeg = "jpeg"


#: Bytes per pixel of a noisy 8-bit image (measured on the default scene: PNG ~0.50, JPEG q95 ~0.18).
_BYTES_PER_PIXEL = {"png": 0.55, "jpeg": 0.2}


def _positions(text: str, select: str | None, mech: str = "delta"):
    import numpy as np

    from ..io import read_csv_columns
    from ..models.presets import POSITION_PRESETS

    cols = ("x", "y", "z") if mech == "delta" else ("x", "y")
    preset = position_preset("--positions", text, mech)
    if preset is not None:
        P = np.asarray(preset, dtype=np.float64)
    elif Path(text).suffix.lower() == ".csv" or Path(text).is_file():
        t = read_csv_columns(text, cols)
        P = t.stack(cols).T
    else:
        try:
            P = np.array([[float(v) for v in item.split(",")] for item in text.split(";") if item.strip()])
        except ValueError:
            P = np.zeros((0, 0))
        if P.ndim != 2 or P.shape[0] == 0 or P.shape[1] != len(cols) or not np.all(np.isfinite(P)):
            presets = ", ".join(k for k, v in POSITION_PRESETS.items() if v[0] == mech)
            c = ",".join(cols)
            raise InputError(
                f"--positions {text!r}: expected a preset ({presets}), a CSV file with columns "
                f"{', '.join(cols)} (mm), or positions '{c};{c}' in mm for the {mech} robot"
            )
    if select:
        try:
            idx = [int(v) for v in select.split(",") if v.strip()]
        except ValueError:
            idx = []
        if not idx or min(idx) < 1 or max(idx) > len(P):
            raise InputError(
                f"--select {select!r}: expected comma-separated position numbers between 1 and {len(P)}"
            )
        dup = sorted({i for i in idx if idx.count(i) > 1})
        if dup:
            raise InputError(f"--select {select!r}: position {dup[0]} is given more than once")
        P = P[[i - 1 for i in idx]]
    return P


def _loads(text: str, g: float):
    import numpy as np

    from ..io import read_csv_columns
    from ..loads import PRESETS, LoadCase, preset

    if text.strip().lower() in PRESETS:
        return preset(text.strip().lower(), g=g)
    if not Path(text).is_file():
        raise InputError(
            f"--loads {text!r}: expected a preset ({', '.join(PRESETS)}) or a CSV file with columns "
            "fx, fy, fz (N) and optionally label"
        )
    t = read_csv_columns(text, ("fx", "fy", "fz"), ("label",), text_columns=("label",))
    F = t.stack(("fx", "fy", "fz")).T
    labels = t.text.get("label", [""] * len(F))
    out_loads = []
    for i, (f, lab) in enumerate(zip(F, labels, strict=True)):
        if not np.any(f):
            raise InputError(f"line {t.lines[i]}: the force is zero", source=text)
        out_loads.append(LoadCase(f, np.zeros((3, 3)), lab or f"F = ({', '.join(f'{v:g}' for v in f)}) N"))
    rank = int(np.linalg.matrix_rank(F, tol=1e-9 * float(np.abs(F).max())))
    if rank < 3:
        raise InputError(
            f"the {len(F)} load(s) span {rank} independent direction(s); 3 are needed to identify "
            "a 3x3 stiffness (add loads along other axes)",
            source=text,
        )
    return out_loads


def _free_workers() -> int:
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # pragma: no cover - not Linux
        return max(os.cpu_count() or 1, 1)


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
}
_SENSOR_ONLY = {"directions": "--directions", "trace_format": "--trace-format"}


def _refuse_options_of_the_other_robot(ctx: typer.Context, robot: RobotName) -> None:
    """An option given for the other kind of simulation is a mistake, not something to ignore."""
    other = _VISION_ONLY if robot is RobotName.prr3 else _SENSOR_ONLY

    def on_command_line(name: str) -> bool:  # click's ParameterSource.COMMANDLINE, by name
        return getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"

    given = [opt for name, opt in other.items() if on_command_line(name)]
    if given:
        what = "the 3PRR's sensor traces" if robot is RobotName.prr3 else "the Delta's camera images"
        raise InputError(
            f"{', '.join(given)}: not used when simulating {what} (--robot {robot.value}); "
            "leave out, or choose the other --robot"
        )


def simulate(
    ctx: typer.Context,
    out_dir: Path = typer.Argument(
        ..., help="Directory to create (must be new or empty).", show_default=False
    ),
    robot: RobotName = typer.Option(
        RobotName.delta,
        "--robot",
        help="Robot model giving the true stiffness field (delta: stiffmap.models).",
    ),
    positions: str = typer.Option(
        None,
        "--positions",
        help="Delta: paper48 (default: the reference study's 48 positions), a CSV file with columns "
        "x, y, z (mm), or 'x,y,z;x,y,z'. 3PRR: points22 (default), a CSV file with x, y, or 'x,y;x,y'.",
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
        "0,0,0", "--load-point-mm", help="Where the loads act, in the tool frame, mm (with a 6x6 field)."
    ),
    param: list[str] = typer.Option(
        [], "--param", help="Robot model parameter NAME=VALUE (repeatable), e.g. k_theta=3e5."
    ),
    camera_file: Path = typer.Option(
        None, "--camera", help="camera.json to simulate instead of the reference camera.", show_default=False
    ),
    truth_only: bool = typer.Option(
        False, "--truth-only", help="Write the spec, camera and truth but no images (fast; for tests)."
    ),
    name: str = typer.Option("virtual test-bed", "--name", help="Campaign name."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary instead of a table."),
) -> None:
    """Simulate a vision campaign of a robot with known stiffness, seen by a known camera.

    Writes OUT_DIR/campaign.toml, camera.json, images/ (an unloaded and a loaded image per
    position, load case and repeat) and the ground truth truth.json (true K at every
    position, every image's poses) with truth_corners.json.gz (true corner pixels).
    The same --seed gives byte-identical files, whatever --workers.
    """
    import numpy as np

    from ..camera import load_camera, reference_camera
    from ..campaign.simulated import check_output_dir, write_campaign
    from ..sim.render import Photometry
    from ..sim.robot import VirtualRobot, delta_robot, with_rotational_compliance
    from ..sim.scene import default_scene
    from ..sim.testbed import SimConfig, plan_campaign
    from ..units import G_REFERENCE_PAPER

    _refuse_options_of_the_other_robot(ctx, robot)
    check_output_dir(out_dir, force)
    command = "stiffmap " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv else ""
    if robot is RobotName.prr3:
        _simulate_sensor(
            out_dir,
            positions,
            select,
            directions,
            repeats,
            seed,
            trace_format,
            force,
            param,
            name,
            command,
            as_json,
        )
        return
    P = _positions(positions or "paper48", select)
    load_cases = _loads(loads, G_REFERENCE_PAPER)
    cam = load_camera(camera_file) if camera_file is not None else reference_camera()
    values = float_values(parse_key_values(param, "--param"), "--param")
    try:
        lp = tuple(float(v) for v in load_point.split(","))
    except ValueError:
        lp = ()
    if len(lp) != 3 or not all(np.isfinite(lp)):
        raise InputError(f"--load-point-mm {load_point!r}: expected x,y,z in mm")
    try:
        base = delta_robot(values)
    except ValueError as e:
        raise InputError(f"--param: {e}") from None
    field = base.field
    if rot_stiffness is not None:
        if rot_stiffness <= 0:
            raise InputError("--rot-stiffness-nmm-per-rad must be positive")
        field = with_rotational_compliance(field, rot_stiffness)
    elif any(lp):
        raise InputError("--load-point-mm needs --rot-stiffness-nmm-per-rad (a 3x3 field has no rotation)")
    vr = VirtualRobot(
        field,
        repeatability_mm=repeatability_mm,
        jitter_mm=jitter_mm,
        load_point_mm=lp,
        model=base.model,
        params=base.params,
    )
    ph = Photometry(blur_px=blur_px, clutter=clutter, colour=colour)
    if not noise:
        ph = Photometry.noise_free(blur_px=blur_px, clutter=clutter, colour=colour)
    try:
        cfg = SimConfig(
            scene=default_scene(cam),
            robot=vr,
            positions=P,
            loads=tuple(load_cases),
            repeats=repeats,
            seed=seed,
            photometry=ph,
            image_format=image_format.value,
            jpeg_quality=jpeg_quality,
            name=name,
            gain_jitter=0.03 if noise else 0.0,
            offset_jitter_dn=1.0 if noise else 0.0,
        )
        plan = plan_campaign(cfg)
    except InputError:
        raise
    except ValueError as e:
        raise InputError(str(e)) from None
    n_images = 0 if truth_only else 2 * len(P) * len(load_cases) * repeats
    w, h = cam.image_size
    need = n_images * w * h * (3 if colour else 1) ** 0.5 * _BYTES_PER_PIXEL[image_format.value]
    probe = (
        out_dir if out_dir.exists() else next((p for p in out_dir.resolve().parents if p.exists()), Path("."))
    )
    free = shutil.disk_usage(probe).free
    if need > 0.95 * free:
        raise InputError(
            f"{n_images} images need about {need / 1e9:.1f} GB but only {free / 1e9:.1f} GB are free; "
            "use fewer --positions/--select/--repeats or --format jpeg",
            source=str(out_dir),
        )
    n_workers = workers or _free_workers()
    if not as_json:
        err.print(
            f"simulating {len(P)} position(s) x {len(load_cases)} load case(s) x {repeats} repeat(s): "
            f"{n_images} images (~{need / 1e9:.2f} GB) with {n_workers} process(es) -> {out_dir}",
            highlight=False,
        )
    t0 = time.perf_counter()
    if as_json or truth_only:
        summary = write_campaign(
            out_dir,
            cfg,
            workers=n_workers,
            force=force,
            render_images=not truth_only,
            command=command,
            plan=plan,
        )
    else:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

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
            task = bar.add_task("images", total=n_images or 1, rate="")

            def progress(done: int, total: int) -> None:
                dt = time.perf_counter() - t0
                rate = f"{done / dt:.2f} images/s" if done and dt > 0 else ""
                bar.update(task, completed=done, total=total or 1, rate=rate)

            summary = write_campaign(
                out_dir, cfg, workers=n_workers, force=force, progress=progress, command=command, plan=plan
            )
    lo, hi = summary.principal_range
    info = {
        "out_dir": str(summary.out_dir),
        "positions": summary.n_positions,
        "load_cases": summary.n_loads,
        "repeats": summary.repeats,
        "images": summary.n_images,
        "format": image_format.value,
        "bytes": summary.bytes_written,
        "seconds": summary.seconds,
        "seed": seed,
        "robot": vr.model,
        "params": vr.params,
        "field": "6x6" if rot_stiffness is not None else "3x3",
        "principal_stiffness_range": [lo, hi],
        "files": list(summary.files),
    }
    if as_json:
        print_json(info)
        return
    print_summary(
        f"simulated campaign in {summary.out_dir}",
        [
            ("images", f"{summary.n_images} {image_format.value} ({summary.bytes_written / 1e6:.1f} MB)"),
            ("positions x loads x repeats", f"{summary.n_positions} x {summary.n_loads} x {summary.repeats}"),
            ("robot", f"{vr.model} ({', '.join(f'{k}={v:g}' for k, v in vr.params.items())})"),
            ("true principal stiffnesses", f"{fmt(lo, 4)} to {fmt(hi, 4)} N/mm"),
            ("seed", str(seed)),
            ("time", f"{summary.seconds:.1f} s"),
            ("files", "campaign.toml, camera.json, truth.json, truth_corners.json.gz, images/"),
        ],
    )


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
    from ..campaign.simulated_sensor import write_sensor_campaign
    from ..models.prr3 import PRR3

    P = _positions(positions or "points22", select, "3prr")
    given = parse_key_values(param, "--param")
    try:
        model = PRR3(**{k: float(v) for k, v in given.items()})
    except ValueError as e:
        raise InputError(f"--param: {e}") from None
    except TypeError:
        bad = sorted(set(given) - set(PRR3.param_names()))
        raise InputError(
            f"--param: unknown 3PRR parameter(s) {', '.join(bad)}; valid: {', '.join(PRR3.param_names())}"
        ) from None
    dirs = tuple(d.strip() for d in directions.split(",") if d.strip())
    fmt = trace_format.strip().lower()
    if fmt not in ("csv", "tdms", "mat"):
        raise InputError(f"--trace-format {trace_format!r}: expected csv, tdms or mat")
    s = write_sensor_campaign(
        out_dir,
        model,
        P,
        directions=dirs,
        repeats=repeats,
        seed=seed,
        fmt=fmt,
        force=force,
        name=name if name != "virtual test-bed" else "virtual test-bed (3PRR, LDV)",
        command=command,
    )
    params = {k: v for k, v in model.params().items()}
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
                "format": fmt,
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
            ("recordings", f"{s.n_recordings} {fmt} ({s.bytes_written / 1e6:.1f} MB)"),
            ("points x axes x repeats", f"{s.n_points} x {len(s.directions)} x {s.repeats}"),
            ("robot", f"3prr ({', '.join(f'{k}={v:g}' for k, v in params.items())})"),
            ("true static errors at 50 kgf", f"{fmt_mm(lo)} to {fmt_mm(hi)} mm"),
            ("seed", str(seed)),
            ("time", f"{s.seconds:.1f} s"),
            ("files", "campaign.toml, truth.json, recordings/ (+ index.csv); run: stiffmap run DIR"),
        ],
    )


def fmt_mm(x: float) -> str:
    return fmt(x, 4)


def register(app: typer.Typer) -> None:
    app.command("simulate")(simulate)
