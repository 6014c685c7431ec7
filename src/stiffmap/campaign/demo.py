"""The demo: the reference experiment on the virtual test-bed, measured by the whole chain.

:func:`run_demo` simulates the reference vision study — the Delta-type robot at
the 48 ``paper48`` positions, the nine ``paper9`` load cases, repeats — as
rendered camera images (:mod:`stiffmap.sim`), runs the campaign exactly as a
user's (:func:`stiffmap.campaign.runner.run_vision_campaign`: detection, poses,
displacements, identification, model fit), writes the exports and the report,
and compares the recovered stiffness with the truth the simulation kept.

The scene is :func:`stiffmap.sim.scene.demo_scene` (a 15x14 board on the
platform, the study's fixed board, the camera 1.0-1.5 m away); the robot stays
at each position while its loads are hung (one unloaded image per repeat, then
one image per load), so each loaded image is compared with the mean unloaded
pose of its position.

As a lab would, the test-bed first renders views of a calibration board
(:mod:`stiffmap.sim.calibration_views`, 20 by default) and the campaign is
measured with the camera calibrated from them (``stiffmap calibrate``'s
calibration), not with the true camera; ``calibration_views=0`` gives it the
true camera instead.

The report is written by the caller (``stiffmap demo`` does it). A directory
that already holds the same simulation (same settings, calibration and seed) is
reused: the images are not rendered again, and the run only does what is missing.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..loads import paper9
from ..models.presets import paper48
from ..sim.robot import delta_robot
from ..sim.scene import demo_scene
from ..sim.testbed import DEFAULT_CALIBRATION_VIEWS, SimConfig
from .export import export_tables
from .runner import run_vision_campaign
from .simulated import write_campaign
from .spec import load_spec
from .store import DB_NAME, Store, remove_database
from .truth import TRUTH_NAME, CalibrationSummary, load_truth

__all__ = ["DemoResult", "run_demo", "demo_config", "demo_command", "QUICK_POSITIONS"]

#: Positions (1-based, in ``paper48``) of the quick demo: a corner and a centre of each plane.
QUICK_POSITIONS = (1, 6, 22, 27, 43, 48)


@dataclass
class DemoResult:
    """What the demo measured, against the truth.

    Attributes
    ----------
    out_dir : Path
    positions : ndarray, shape (n, 3), mm
    K_true, K_measured : ndarray, shape (n, 3, 3), N/mm (NaN where a position failed)
    rel_error : ndarray, shape (n,)
        ||K_measured - K_true||_F / ||K_true||_F per position (NaN where failed).
    simulated : bool
        False when an earlier identical simulation was reused.
    images : int
    seconds_simulate, seconds_run : float
    calibration : CalibrationSummary
        How the campaign's camera.json was obtained (from truth.json).
    failures : list of str
    """

    out_dir: Path
    positions: np.ndarray
    K_true: np.ndarray
    K_measured: np.ndarray
    rel_error: np.ndarray
    simulated: bool
    images: int
    seconds_simulate: float
    seconds_run: float
    calibration: CalibrationSummary
    failures: list[str] = field(default_factory=list)

    @property
    def worst_percent(self) -> float:
        """Worst relative Frobenius error over all positions, % (inf when a position failed)."""
        e = self.rel_error
        return float("inf") if np.any(~np.isfinite(e)) else float(100 * e.max())


def demo_config(
    *,
    quick: bool = False,
    repeats: int | None = None,
    seed: int = 1,
    calibration_views: int = DEFAULT_CALIBRATION_VIEWS,
) -> SimConfig:
    """The :class:`~stiffmap.sim.testbed.SimConfig` of the demo.

    ``calibration_views``: views of the calibration board from which the campaign's camera
    is calibrated (0: the campaign gets the true camera).
    """
    pos = paper48()
    if quick:
        pos = pos[np.asarray(QUICK_POSITIONS) - 1]
    r = repeats if repeats is not None else (2 if quick else 3)
    return SimConfig(
        scene=demo_scene(),
        robot=delta_robot(),
        positions=pos,
        loads=tuple(paper9()),
        repeats=r,
        seed=seed,
        robot_stays=True,
        calibration_views=calibration_views,
        name="demo: the reference experiment on the virtual test-bed" + (" (quick)" if quick else ""),
    )


def demo_command(config: SimConfig, quick: bool) -> str:
    """What truth.json records as the demo's command: every setting the simulation depends on.

    The calibration is part of what is simulated: a directory simulated with another
    calibration setting (or before there were calibration views) is simulated again.
    """
    return (
        f"stiffmap demo (quick={quick}, repeats={config.repeats}, seed={config.seed}, "
        f"calibration_views={config.calibration_views})"
    )


def _same_simulation(out: Path, command: str) -> bool:
    t = out / TRUTH_NAME
    if not t.is_file():
        return False
    try:
        d = json.loads(t.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return d.get("generator", {}).get("command") == command


def run_demo(
    out_dir: str | Path,
    *,
    quick: bool = False,
    repeats: int | None = None,
    seed: int = 1,
    calibration_views: int = DEFAULT_CALIBRATION_VIEWS,
    workers: int = 1,
    fresh: bool = False,
    sim_progress: Callable[[int, int], None] | None = None,
    run_progress: Callable[[int, int, int], None] | None = None,
) -> DemoResult:
    """Simulate, measure, identify, export, and compare with the truth.

    The report (``stiffmap.report.campaign.write_campaign_report``) is the
    caller's to write: the report layer sits above this one.

    Parameters
    ----------
    out_dir : path
        The demo campaign's directory (created; a previous demo there is reused or,
        with ``fresh``, simulated again).
    quick : bool
        Six positions and two repeats instead of 48 and three (for tests).
    repeats : int, optional
    seed : int
    calibration_views : int
        Views of the calibration board the camera is calibrated from (0: the true camera).
    workers : int
        Processes for rendering and for measuring.
    fresh : bool
        Simulate again even when the same simulation is there.

    Raises
    ------
    InputError
        When ``out_dir`` holds something else than a stiffmap simulation.
    """
    out = Path(out_dir)
    config = demo_config(quick=quick, repeats=repeats, seed=seed, calibration_views=calibration_views)
    command = demo_command(config, quick)
    simulated = False
    t0 = time.perf_counter()
    if fresh or not _same_simulation(out, command):
        if out.exists() and any(out.iterdir()) and not (out / TRUTH_NAME).is_file():
            raise InputError("not empty and not a previous demo; choose another directory", source=str(out))
        remove_database(out)  # results of another simulation: never mix them
        write_campaign(out, config, workers=workers, force=True, progress=sim_progress, command=command)
        simulated = True
    t1 = time.perf_counter()
    summary = run_vision_campaign(out, workers=workers, progress=run_progress)
    spec = load_spec(out)
    truth = load_truth(out)
    with Store(out / DB_NAME) as store:
        export_tables(store, out / "exports", spec.name, summary.failures)
        rows = store.stiffness_rows()
    t2 = time.perf_counter()
    n = len(truth.K)
    K = np.full((n, 3, 3), np.nan)
    for r in rows:
        if r.status == "ok" and 1 <= r.position <= n:
            K[r.position - 1] = r.K
    err = np.linalg.norm(K - truth.K, axis=(1, 2)) / np.linalg.norm(truth.K, axis=(1, 2))
    return DemoResult(
        out_dir=out,
        positions=truth.positions,
        K_true=truth.K,
        K_measured=K,
        rel_error=err,
        simulated=simulated,
        images=summary.images,
        seconds_simulate=t1 - t0,
        seconds_run=t2 - t1,
        calibration=truth.calibration,
        failures=summary.failures,
    )
