"""``stiffmap demo``: the reference experiment on the virtual test-bed, end to end (``make demo``)."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np
import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

from ..campaign.demo import DemoResult, run_demo
from ..parallel import local_workers
from ..report.campaign import write_campaign_report
from ..sim.testbed import DEFAULT_CALIBRATION_VIEWS
from .common import EXIT_PARTIAL, err, out, warn


def demo(
    out_dir: Path = typer.Argument(
        Path("demo-out"), help="Directory of the demo campaign (reused if it holds it)."
    ),
    quick: bool = typer.Option(
        False, "--quick", help="6 positions and 2 repeats instead of 48 and 3 (a minute)."
    ),
    repeats: int = typer.Option(
        0, "--repeats", min=0, help="Repeats per load case (0: 3, or 2 with --quick)."
    ),
    seed: int = typer.Option(1, "--seed", min=0, help="Seed of the simulation."),
    workers: int = typer.Option(0, "--workers", "-w", min=0, help="Processes (0: all CPUs)."),
    fresh: bool = typer.Option(False, "--fresh", help="Simulate again even if OUT_DIR holds this demo."),
    true_camera: bool = typer.Option(
        False,
        "--true-camera",
        help=f"Measure with the true camera instead of one calibrated from {DEFAULT_CALIBRATION_VIEWS} "
        "rendered views of a calibration board (the default, as a lab does).",
    ),
    report: bool = typer.Option(True, "--report/--no-report", help="Write OUT_DIR/report/."),
) -> None:
    """Simulate the reference experiment and measure it with the whole chain.

    The virtual test-bed renders the camera images of a Delta-type robot with a known
    stiffness at the reference study's 48 positions under its nine load cases, with
    repeats, and views of a calibration board from which the camera is calibrated as a
    lab would; stiffmap then runs the campaign as it would a real one (board detection,
    poses, displacements, stiffness identification, model fit, exports, report) with
    that calibrated camera and prints the recovered stiffness against the truth at every
    position, ending with the worst relative error (Frobenius norm) over all positions.
    """
    with _demo_progress() as (sim_hook, run_hook):
        res = run_demo(
            out_dir,
            quick=quick,
            repeats=repeats or None,
            seed=seed,
            calibration_views=0 if true_camera else DEFAULT_CALIBRATION_VIEWS,
            workers=workers or local_workers(),
            fresh=fresh,
            sim_progress=sim_hook,
            run_progress=run_hook,
        )
    if not res.simulated:
        err.print(f"reused the simulation already in {out_dir} (--fresh to simulate again)")
    _print_demo(res)
    if report:
        out.print(f"report: {write_campaign_report(res.out_dir, res.failures)}")
    for f in res.failures:
        warn(f)
    out.print(f"worst relative K error: {res.worst_percent:.2f} %")
    if res.failures or not np.isfinite(res.worst_percent):
        raise typer.Exit(EXIT_PARTIAL)


@contextmanager
def _demo_progress():
    """Progress bars of the rendering and the measuring on stderr; yields their two hooks."""
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeRemainingColumn(),
        console=err,
    ) as prog:
        sim = prog.add_task("rendering images", total=None, rate="")
        meas = prog.add_task("measuring images", total=None, rate="", visible=False)

        def sim_hook(done: int, total: int) -> None:
            t = prog.tasks[sim]
            rate = f"{done / t.elapsed:.1f} images/s" if t.elapsed else ""
            prog.update(sim, completed=done, total=total, rate=rate)

        def run_hook(done: int, total: int, measured: int) -> None:
            t = prog.tasks[meas]
            rate = f"{measured / t.elapsed:.1f} images/s" if t.elapsed and measured else ""
            prog.update(meas, completed=done, total=total, rate=rate, visible=True)

        yield sim_hook, run_hook


def _print_demo(res: DemoResult) -> None:
    """Recovered against true K at every position, and the images and times."""
    t = Table(title="recovered against true stiffness (N/mm), base frame")
    for col in ("#", "position (mm)", "true K (rows)", "recovered K (rows)", "error"):
        t.add_column(col, no_wrap=True)
    for i, p in enumerate(res.positions):
        true = "\n".join(" ".join(f"{v:6.2f}" for v in row) for row in res.K_true[i])
        got = (
            "\n".join(" ".join(f"{v:6.2f}" for v in row) for row in res.K_measured[i])
            if np.all(np.isfinite(res.K_measured[i]))
            else "[red]failed[/]"
        )
        e = res.rel_error[i]
        t.add_row(
            str(i + 1),
            ", ".join(f"{v:.0f}" for v in p),
            true,
            got,
            f"{100 * e:.2f} %" if np.isfinite(e) else "n/a",
        )
    out.print(t, width=max(out.width, 100))
    out.print(
        f"{len(res.positions)} positions, {res.images} images measured; "
        f"simulate {res.seconds_simulate:.0f} s, measure + identify {res.seconds_run:.0f} s"
    )
    out.print(res.calibration.describe(), highlight=False)


def register(app: typer.Typer) -> None:
    app.command("demo")(demo)
