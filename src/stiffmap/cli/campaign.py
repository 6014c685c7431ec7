"""``stiffmap init`` and ``stiffmap run``: campaign directories from spec to report.

``run`` is :func:`stiffmap.campaign.run.run_and_export` then the report
(:func:`stiffmap.report.campaign.write_campaign_report`); ``init --from-demo`` writes
the quick demo's simulation (:func:`stiffmap.campaign.demo.demo_config`).
"""

from __future__ import annotations

import shlex
import time
from enum import StrEnum
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from ..campaign.demo import demo_config
from ..campaign.export import calibration_share_of_K, summary_dict
from ..campaign.instruments import STIFFNESS, instrument_of
from ..campaign.paths import ALLOW_OUTSIDE_OPTION
from ..campaign.run import CampaignRun, campaign_root, run_and_export
from ..campaign.runner import RunSummary
from ..campaign.sensor_runner import measured_static_errors
from ..campaign.simulated import check_output_dir, write_campaign
from ..campaign.spec import SPEC_NAME, load_spec
from ..campaign.spec_writer import EXAMPLE_TOML
from ..campaign.store import Store
from ..errors import InputError
from ..io import atomic_write_text
from ..kinds import robot_kind
from ..parallel import local_workers
from ..report.campaign import write_campaign_report
from ..textfmt import fmt_pm
from .common import EXIT_PARTIAL, dask_option, fmt, images_progress, note, out, print_json, warn


class MethodName(StrEnum):
    compliance = "compliance"
    paper = "paper"
    spd = "spd"


#: Failures printed one per line; more are counted in one line (exports/summary.json lists all).
MAX_WARNINGS = 50


def init(
    directory: Path = typer.Argument(
        ..., help="Campaign directory (created if needed; it may already hold the images)."
    ),
    from_demo: bool = typer.Option(
        False,
        "--from-demo",
        help="Instead of the template, the demo's campaign, complete: the quick demo set-up (6 of "
        "the reference positions, nine loads, two repeats) simulated into DIRECTORY with its "
        "images, the calibration views and the camera.json calibrated from them, and truth.json, "
        "ready for 'stiffmap run'. DIRECTORY must be new or empty.",
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing campaign.toml."),
) -> None:
    """Write a commented example campaign.toml to start a campaign from.

    Edit it (boards, fixed2base, positions, loads, image names), put camera.json and the
    images beside it, then run: stiffmap run DIRECTORY. With --from-demo, a complete
    simulated campaign to try the whole chain on first.
    """
    path = directory / SPEC_NAME
    if from_demo:
        _init_from_demo(directory, force)
        out.print(
            f"wrote {path}, calibration/ and the camera.json calibrated from it, images/ and "
            "truth.json (the true stiffness and camera)"
        )
        out.print("next: stiffmap run " + shlex.quote(str(directory)))
        return
    if path.exists() and not force:
        raise InputError(f"{path} already exists; use --force to overwrite it")
    atomic_write_text(path, EXAMPLE_TOML)
    out.print(f"wrote {path}")
    out.print(
        "next: edit it, add camera.json and the images, then: stiffmap run " + shlex.quote(str(directory))
    )


def _init_from_demo(directory: Path, force: bool) -> None:
    """Simulate the quick demo campaign into ``directory`` (progress on stderr)."""
    check_output_dir(directory, force)
    with images_progress("rendering images") as update:
        write_campaign(
            directory,
            demo_config(quick=True),
            workers=local_workers(),
            force=force,
            progress=lambda done, total: update(done, total, done),
            command=f"stiffmap init {directory} --from-demo",
        )


def _summary_table(store: Store) -> Table:
    t = Table(title="stiffness per position (N/mm)", show_lines=False)
    for col in ("#", "x, y, z (mm)", "K (rows)", "det K", "min principal", "flags"):
        t.add_column(col, no_wrap=col != "flags")
    for r in store.stiffness_rows():
        xyz = f"{r.x:.0f}, {r.y:.0f}, {r.z:.0f}"
        if r.status != "ok":
            t.add_row(str(r.position), xyz, "[red]failed[/]", "", "", r.error or "")
            continue
        K = r.K
        rows = "\n".join(" ".join(f"{v:7.3f}" for v in row) for row in K)
        flags = r.flags or []
        t.add_row(
            str(r.position),
            xyz,
            rows,
            fmt(r.det, 4),
            fmt(r.min_principal, 4),
            "[yellow]" + "\n".join(flags) + "[/]" if flags else "none",
        )
    return t


def _fit_table(store: Store, model: str) -> Table | None:
    """The model's parameters fitted to a vision campaign (None when there is no fit)."""
    fit = store.model_fit("stiffness")
    if fit is None or fit.status != "ok":
        return None
    est = fit.params
    std = fit.std or {}
    what = "joint stiffnesses (N*mm/rad)" if robot_kind(model).joint_params else "parameters"
    t = Table(title=f"{model} model: {what} fitted", show_lines=False)
    t.add_column("parameter")
    t.add_column("estimate ± standard error", justify="right")
    t.add_column("relative", justify="right")
    for k, v in est.items():
        s = std.get(k, float("nan"))
        t.add_row(k, fmt_pm(v, s), f"{100 * s / v:.2g} %" if v and s == s else "")
    return t


def _sensor_table(spec, store: Store) -> Table:
    m = measured_static_errors(spec, store)
    pred = store.model_static_errors()
    fit = store.model_fit("static_error")
    title = f"static error at {fmt(m['reference_load_n'], 4)} N (um)"
    model_col = "model"
    if fit is not None and fit.status == "ok":
        est, std = fit.params, fit.std
        title += "; model fit: " + ", ".join(f"{k} = {fmt(v, 5)} ± {fmt(std[k], 2)}" for k, v in est.items())
        model_col = "model (fitted)"
    elif fit is not None:
        title += "; model fit failed: the model column uses the parameters of campaign.toml"
        model_col = "model (not fitted)"
    t = Table(title=title)
    for col in ("recording", "point (mm)", "direction", "measured", "± std", model_col, "flags"):
        t.add_column(col, overflow="fold")
    for i, f in enumerate(m["files"]):
        p = pred.get(f)
        t.add_row(
            escape(f),
            ", ".join(f"{x:g}" for x in m["points"][i]),
            ", ".join(f"{x:g}" for x in m["directions"][i]),
            fmt(1e3 * m["value_mm"][i], 5) if m["valid"][i] else "[red]failed[/]",
            fmt(1e3 * m["std_mm"][i], 2) if m["valid"][i] else "",
            fmt(1e3 * p, 5) if p is not None else "",
            "[yellow]" + escape("; ".join(m["flags"][i])) + "[/]" if m["flags"][i] else "",
        )
    return t


def run(
    campaign: Path = typer.Argument(..., help="Campaign directory (holding campaign.toml)."),
    workers: int = typer.Option(
        0,
        "--workers",
        "-w",
        min=0,
        help="Worker processes for image work (0: all CPUs); with --dask local, the local cluster's workers.",
    ),
    dask: str | None = dask_option(
        "Measure the images (workers read them from the campaign directory when they see it, "
        "else this machine sends them)"
    ),
    send_images: bool = typer.Option(
        False,
        "--send-images",
        help="With --dask: send the images to the workers even when they see the campaign "
        "directory (shared storage slower than the network).",
    ),
    method: MethodName = typer.Option(
        MethodName.compliance, "--method", help="Stiffness identification method."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the JSON summary instead of tables."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write CAMPAIGN/report/ (HTML + PNG)."),
    allow_outside_paths: bool = typer.Option(
        False,
        ALLOW_OUTSIDE_OPTION,
        help="Let campaign.toml name files outside CAMPAIGN (absolute paths, '..', symbolic links "
        "leading out); without it such a name is refused.",
    ),
) -> None:
    """Measure, identify, fit and export a campaign (resumable: a re-run does only what changed).

    Vision campaigns: every image's boards and poses, the compliant displacement of each load
    case and repeat, K per position with standard errors and flags, the model fit.
    Sensor campaigns: every recording's steps, fit and static error, the model fit.
    Results go to CAMPAIGN/stiffmap.db, tables to CAMPAIGN/exports/ (CSV, Parquet, summary.json),
    the report to CAMPAIGN/report/index.html (self-contained, opens offline) with PNG figures.

    Exit status: 0 all done, 1 done with failures (listed: a K asymmetric by Holm's test at
    1 % over the positions, not positive definite or det <= 0 is one; Cochran's outliers
    are review flags, in the tables), 2 nothing could be done (a bad spec or camera file,
    or no position or recording could be measured).
    """
    root = campaign_root(campaign)
    spec = load_spec(root)
    t0 = time.perf_counter()
    instrument = instrument_of(spec)
    with images_progress("measuring images", show=instrument.per_image and not quiet) as hook:
        done = run_and_export(
            root,
            spec=spec,
            workers=workers or local_workers(),
            method=method.value,
            progress=hook,
            allow_outside=allow_outside_paths,
            dask=dask,
            send_images=send_images,
        )
    nothing = done.nothing_measured()
    _print_results(done, spec, instrument, as_json=as_json, tables=nothing is None)
    if nothing is not None:  # one line with the first failures; summary.json lists them all
        raise InputError(nothing + "; no report written", source=str(done.root))
    page = (
        write_campaign_report(done.root, done.failures, allow_outside=allow_outside_paths) if report else None
    )
    _print_warnings(done)  # the warnings first, then the summary that ends with "done" (read last)
    if not as_json:
        _print_counts(done, page, time.perf_counter() - t0)
    if done.failures:
        raise typer.Exit(EXIT_PARTIAL)


def _print_results(done, spec, instrument, *, as_json: bool, tables: bool) -> None:
    """The run's JSON summary, or its tables (K per position and the model fit, or the
    sensor recordings) when something was measured."""
    with Store(done.db) as store:
        if as_json:
            print_json(summary_dict(store, spec.name, done.failures, done.vision.info if done.vision else ()))
        elif not tables:
            pass
        elif instrument.measures == STIFFNESS:
            out.print(_summary_table(store))
            out.print(_calibration_line(calibration_share_of_K(store), done.vision))
            fitted = _fit_table(store, spec.robot.model)
            if fitted is not None:
                out.print(fitted)
        else:
            out.print(_sensor_table(spec, store))


def _print_warnings(done) -> None:
    """The run's notes and failures (the first :data:`MAX_WARNINGS`; summary.json has them all)."""
    for n in done.vision.notes if done.vision is not None else ():
        warn(n)
    for n in done.vision.info if done.vision is not None else ():
        note(n)
    for f in done.failures[:MAX_WARNINGS]:
        warn(f)
    if len(done.failures) > MAX_WARNINGS:
        warn(
            f"... and {len(done.failures) - MAX_WARNINGS} more failures, all listed in "
            f"{done.exports / 'summary.json'}"
        )


def _calibration_line(share: tuple[float, float] | None, run: RunSummary | None) -> str:
    """How much of K's uncertainty is the camera calibration's (or why that is not known)."""
    if share is None and run is not None and run.calibration_known:
        return (
            f"the camera calibration's share of K's uncertainty is unknown: {run.camera_file} gives "
            "it, but no position has an uncertainty of K (see the flags: too few load cases, or "
            "failures)"
        )
    if share is None:
        name = run.camera_file if run is not None and run.camera_file else "the camera file"
        return (
            f"K's uncertainty leaves out the camera calibration's: {name} gives no covariance "
            "or std (calibrate with 'stiffmap calibrate' or 'stiffmap calibrate-rig' to include it)"
        )
    return (
        f"camera calibration's share of the variance of k11, k22, k33: median {100 * share[0]:.1f} %, "
        f"largest {100 * share[1]:.1f} % (common to every position: it does not average out)"
    )


def _print_counts(done: CampaignRun, page: Path | None, seconds: float) -> None:
    """What was measured or reused, where the results are, and the time taken."""
    if done.vision is not None:
        summary = done.vision
        rate = summary.images / summary.wall_seconds if summary.wall_seconds > 0 and summary.images else 0
        out.print(
            f"{summary.positions} positions: {summary.measured} measured ({summary.images} images, "
            f"{rate:.1f} images/s), "
            + (f"{summary.rederived} re-derived (images unchanged), " if summary.rederived else "")
            + f"{summary.reused} unchanged since the last run"
        )
        if summary.measured:
            out.print(f"measured on {summary.backend}", highlight=False)
    else:
        res = done.sensor
        out.print(f"{res.recordings} recordings: {res.analysed} analysed, {res.reused} unchanged")
    out.print(f"results: {done.db}; tables: {done.exports}")
    if page is not None:
        out.print(f"report: {page}")
    out.print(f"done in {seconds:.1f} s")


def register(app: typer.Typer) -> None:
    app.command("init")(init)
    app.command("run")(run)
