"""``stiffmap sensor``: displacement-sensor recordings of stepped loads to stiffness and static error."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer
from rich.table import Table

from ..errors import InputError
from ..io import ALLOW_OUTSIDE_OPTION
from ..sensors import analyse_batch, read_measurement_index
from ..textfmt import fmt, fmt_pm
from .common import EXIT_INPUT, EXIT_PARTIAL, fail, out, print_json, warn
from .sensor_options import config_from_options, sensor_option_names


class LoadUnit(StrEnum):
    kgf = "kgf"
    N = "N"
    V = "V"


def _print_result(r) -> None:
    f = r.fit
    t = Table(
        title=f"{r.source}: {len(r.plateaus)} plateaus, {fmt(r.sample_rate_hz, 4)} Hz, "
        f"noise {fmt(1e3 * r.noise_mm, 2)} um",
        title_justify="left",
    )
    for col in ("#", "time (s)", "load (N)", "displacement (um)", "std (um)", "n", "branch"):
        t.add_column(col, justify="right" if col not in ("branch",) else "left")
    for i, p in enumerate(r.plateaus):
        t.add_row(
            str(i + 1),
            f"{p.t_start_s:.2f}-{p.t_end_s:.2f}",
            fmt(p.load_n, 5),
            fmt(1e3 * p.displacement_mm, 5),
            fmt(1e3 * p.std_mm, 2),
            str(p.n),
            p.branch,
        )
    out.print(t)
    s = Table(show_header=False, box=None)
    lo, hi = f.stiffness_ci_n_per_mm
    s.add_row(
        "stiffness",
        f"{fmt_pm(f.stiffness_n_per_mm, f.stiffness_std_n_per_mm)} N/mm "
        f"({100 * f.level:g} % CI {fmt(lo)} to {fmt(hi)})",
    )
    s.add_row(
        "compliance",
        f"{fmt_pm(1e3 * f.compliance_mm_per_n, 1e3 * f.compliance_std_mm_per_n)} um/N, "
        f"intercept {fmt(1e3 * f.intercept_mm, 4)} um, R^2 {f.r2:.6f}",
    )
    s.add_row(
        f"static error at {fmt(r.reference_load_n)} N",
        f"{fmt_pm(1e3 * r.static_error_mm, 1e3 * r.static_error_std_mm)} um",
    )
    h = r.hysteresis
    s.add_row(
        "hysteresis",
        "n/a (needs loading and unloading plateaus)"
        if h is None
        else f"{fmt(1e3 * h.max_mm, 3)} um at {fmt(h.at_load_n, 4)} N ({fmt(100 * h.ratio, 2)} % of span)",
    )
    s.add_row("drift removed", "n/a" if r.drift_mm != r.drift_mm else f"{fmt(1e3 * r.drift_mm, 3)} um")
    s.add_row("flags", "none" if not r.flags else r.flags[0])
    for fl in r.flags[1:]:
        s.add_row("", fl)
    out.print(s)


# The options of `sensor` (declared here so that the command's signature reads at once).
_OPT_RECORDINGS = typer.Argument(
    None,
    help="Recordings (.csv, .tdms, .mat) of a displacement sensor (V) and a load channel, during a "
    "stepped load. Default CSV columns: time_s, displacement_v, load_kgf.",
    show_default=False,
)
_OPT_SCALE_UM_PER_V = typer.Option(
    640.0, "--scale-um-per-v", help="Displacement sensor scale, um/V (the milling study's LDV: 640)."
)
_OPT_CHANNEL_MAP = typer.Option(
    None,
    "--channel-map",
    help="Which column is what: displacement=COL,load=COL,time=COL[,rate=HZ][,group=NAME]. "
    "load=none: no load channel; time=none with rate=HZ: no time column.",
)
_OPT_LOAD_UNIT = typer.Option(
    None,
    "--load-unit",
    help="Unit of the load channel (default: from its name, load_kgf / force_n; else kgf).",
)
_OPT_LOAD_N_PER_V = typer.Option(None, "--load-n-per-v", help="Load-cell scale when the load is in V, N/V.")
_OPT_STEPS_KGF = typer.Option(
    None, "--steps-kgf", help="Table of the applied loads in time order, kgf (e.g. 0,50,40,30,20,10,0)."
)
_OPT_STEPS_N = typer.Option(None, "--steps-n", help="Table of the applied loads in time order, N.")
_OPT_STEP_TIMES = typer.Option(
    None, "--step-times", help="Plateaus by hand, START-END in s, comma-separated (e.g. 0.5-4,6-9.5)."
)
_OPT_AXIS_SIGN = typer.Option(1, "--axis-sign", help="-1 when a mirror flips the beam.")
_OPT_RANGE_V = typer.Option(8.0, "--range-v", help="Sensor analog output range, +-V (saturation).")
_OPT_G = typer.Option(9.81, "--g", help="Gravity for kgf, m/s^2 (9.81 as the milling study).")
_OPT_REFERENCE_LOAD_N = typer.Option(
    490.5, "--reference-load-n", help="Load of the static error, N (50 kgf = 490.5 N)."
)
_OPT_EXCLUDE_BAD_SAMPLES = typer.Option(
    False,
    "--exclude-bad-samples",
    help="Leave missing samples (dropouts) out of the plateaus instead of refusing the recording; "
    "saturated plateaus are still refused.",
)
_OPT_NO_DRIFT = typer.Option(False, "--no-drift-removal", help="Do not remove drift via zero-load plateaus.")
_OPT_WINDOW_S = typer.Option(0.25, "--window-s", help="Window of the step detector, s.")
_OPT_MIN_PLATEAU_S = typer.Option(0.5, "--min-plateau-s", help="Shortest plateau kept, s.")
_OPT_THRESHOLD_SIGMA = typer.Option(5.0, "--threshold-sigma", help="Step detector threshold, in sigma.")
_OPT_INDEX = typer.Option(
    None,
    "--index",
    help="A campaign index CSV (x, y[, z], direction or ux, uy[, uz], file[, axis_sign]): print the "
    "static error per point and direction.",
)
_OPT_AS_JSON = typer.Option(False, "--json", help="Print a JSON list, one object per recording.")
_OPT_ALLOW_OUTSIDE_PATHS = typer.Option(
    False,
    ALLOW_OUTSIDE_OPTION,
    help="Let the --index file name recordings outside its folder (absolute paths, '..', symbolic "
    "links leading out); without it such a name is refused.",
)


def sensor(
    recordings: list[Path] = _OPT_RECORDINGS,
    scale_um_per_v: float = _OPT_SCALE_UM_PER_V,
    channel_map: str = _OPT_CHANNEL_MAP,
    load_unit: LoadUnit = _OPT_LOAD_UNIT,
    load_n_per_v: float = _OPT_LOAD_N_PER_V,
    steps_kgf: str = _OPT_STEPS_KGF,
    steps_n: str = _OPT_STEPS_N,
    step_times: str = _OPT_STEP_TIMES,
    axis_sign: int = _OPT_AXIS_SIGN,
    range_v: float = _OPT_RANGE_V,
    g: float = _OPT_G,
    reference_load_n: float = _OPT_REFERENCE_LOAD_N,
    exclude_bad_samples: bool = _OPT_EXCLUDE_BAD_SAMPLES,
    no_drift: bool = _OPT_NO_DRIFT,
    window_s: float = _OPT_WINDOW_S,
    min_plateau_s: float = _OPT_MIN_PLATEAU_S,
    threshold_sigma: float = _OPT_THRESHOLD_SIGMA,
    index: Path = _OPT_INDEX,
    as_json: bool = _OPT_AS_JSON,
    allow_outside_paths: bool = _OPT_ALLOW_OUTSIDE_PATHS,
) -> None:
    """Plateaus, load-displacement fit, stiffness and static error of stepped-load recordings.

    For each recording: the static plateaus (mean, std, n; found automatically, robust to noise and
    slow drift, or given with --step-times), the drift removed through the zero-load plateaus, the
    least-squares line (stiffness N/mm, compliance, intercept, R^2, confidence interval), the
    hysteresis between loading and unloading, and the static error at the reference load.

    A recording that saturates, has a dropout or has fewer plateaus than the table of steps is
    reported (file and time span) and the others go on. Exit status: 0 all recordings analysed,
    1 some failed, 2 none could be analysed (or a bad option).
    """
    try:
        cmap, cfg = config_from_options(
            channel_map,
            steps_kgf=steps_kgf,
            steps_n=steps_n,
            step_times=step_times,
            load_unit=None if load_unit is None else load_unit.value,
            load_n_per_v=load_n_per_v,
            scale_um_per_v=scale_um_per_v,
            range_v=range_v,
            axis_sign=axis_sign,
            g=g,
            reference_load_n=reference_load_n,
            window_s=window_s,
            min_plateau_s=min_plateau_s,
            threshold_sigma=threshold_sigma,
            remove_drift=not no_drift,
            exclude_bad_samples=exclude_bad_samples,
        )
        if not recordings and index is None:
            raise InputError("give one or more recordings, or --index FILE")
        entries = (
            read_measurement_index(index, allow_outside=allow_outside_paths) if index is not None else None
        )
    except InputError as e:
        raise fail(str(e), EXIT_INPUT) from None
    names = sensor_option_names(steps_n=bool(steps_n) and not steps_kgf)
    batch = analyse_batch(recordings or [], entries, cmap, cfg, names)
    if as_json:
        print_json(batch.to_json())
        _warn_failed_recordings(batch)
    else:
        _print_batch(batch)
    _warn_failed_entries(batch)
    if batch.n_ok == 0:
        n = batch.n_failed
        raise fail(f"none of the {n} recording(s) could be analysed (each is named above)", EXIT_INPUT)
    if batch.n_failed:
        raise typer.Exit(EXIT_PARTIAL)


def _warn_failed_recordings(batch) -> None:
    """One ``warning:`` line per recording that could not be used (its file and why)."""
    for r in batch.results:
        if isinstance(r, InputError):
            warn(f"{r} (skipped)")


def _warn_failed_entries(batch) -> None:
    """One ``warning:`` line per index entry whose recording could not be used."""
    ses = batch.static_errors
    if ses is None:
        return
    for f, ok, reason in zip(ses.files, ses.valid, ses.reasons, strict=True):
        if not ok:
            warn(f"{reason if reason.startswith(f) else f'{f}: {reason}'} (skipped)")


def _print_batch(batch) -> None:
    """Each recording's tables (or its error as a warning), then the index's static errors."""
    for r in batch.results:
        if isinstance(r, InputError):
            warn(f"{r} (skipped)")
        else:
            _print_result(r)
    ses = batch.static_errors
    if ses is None:
        return
    d = ses.points.shape[1]
    t = Table(title=f"static error at {fmt(ses.reference_load_n)} N along the load", title_justify="left")
    for c in ("x", "y", "z")[:d]:
        t.add_column(f"{c} (mm)", justify="right")
    t.add_column("direction")
    t.add_column("static error (um)", justify="right")
    t.add_column("stiffness (N/mm)", justify="right")
    t.add_column("file / error")
    for i, row in enumerate(ses.to_rows()):
        u = ses.directions[i]
        t.add_row(
            *(fmt(ses.points[i, j], 5) for j in range(d)),
            "(" + ", ".join(fmt(x, 3) for x in u) + ")",
            fmt_pm(row["static_error_um"], row["static_error_std_um"]) if ses.valid[i] else "-",
            fmt(row["stiffness_n_per_mm"]) if ses.valid[i] else "-",
            Path(row["file"]).name if ses.valid[i] else ses.reasons[i],
        )
    out.print(t)
    for row in ses.to_rows():
        for flag in row["flags"]:
            warn(f"{row['file']}: {flag}")


def register(app: typer.Typer) -> None:
    app.command("sensor")(sensor)
