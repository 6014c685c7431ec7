"""The six-joint arm's joint stiffnesses from simulated vision campaigns, against the truth.

As a user would: ``stiffmap simulate OUT --robot arm6 --seed S`` (stiffmap's six-joint arm from
its URDF, 20 positions in front of it, the tool pointing down; the reference study's nine load
cases, hung 100 mm below and 50 mm beside the measured point; 3 repeats; one camera calibrated
from its own rendered views) then ``stiffmap run OUT``, which measures every image and fits the
six joint stiffnesses k1..k6 to the measured displacements (translations and rotations, with
their covariances: models.joint_fit). Over several seeds, per joint: the largest error against
the truth, the mean standard error the fit reports, and the scatter of the estimates over the
seeds (their standard deviation about the truth, sqrt(mean((k - k_true)^2))). Standard errors
that are right make the ratio scatter / reported about 1; with few seeds it is itself uncertain
(a chi-square of 6 x seeds values: the pooled ratio over the six joints is what to read).

Run:  .venv/bin/python benchmarks/bench_arm_joints.py [--seeds 5] [--workers 2]
Saves benchmarks/results/arm_joints.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

sys.path.insert(0, str(HERE))
from _table import save  # noqa: E402

from stiffmap.campaign.store import DB_NAME, Store  # noqa: E402
from stiffmap.cli.main import main as stiffmap  # noqa: E402
from stiffmap.models import arm6  # noqa: E402


def campaign(root: Path, seed: int, workers: int) -> dict:
    t0 = time.perf_counter()
    rc = stiffmap(
        ["simulate", str(root), "--robot", "arm6", "--seed", str(seed), "--workers", str(workers), "--json"]
    )
    t_sim = time.perf_counter() - t0
    if rc not in (0, None):
        raise SystemExit(f"simulate failed ({rc})")
    t0 = time.perf_counter()
    rc = stiffmap(["run", str(root), "--workers", str(workers), "--json"])
    t_run = time.perf_counter() - t0
    with Store(root / DB_NAME) as st:
        fit = st.model_fit("stiffness")
    if fit is None or fit.status != "ok":
        raise SystemExit(f"seed {seed}: the joint fit failed: {None if fit is None else fit['error']}")
    est = fit.params
    std = fit.std
    names = [f"k{i}" for i in range(1, 7)]
    return {
        "k": np.array([est[n] for n in names]),
        "std": np.array([std[n] for n in names]),
        "simulate_s": t_sim,
        "run_s": t_run,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    truth = np.array(arm6.K_THETA)
    runs = []
    for seed in range(args.seeds):
        with tempfile.TemporaryDirectory(prefix="bench_arm_") as tmp:
            r = campaign(Path(tmp) / "arm", seed, args.workers)
        runs.append(r)
        err = 100 * (r["k"] / truth - 1)
        z = np.round((r["k"] - truth) / r["std"], 2).tolist()
        print(f"seed {seed}: errors % {np.round(err, 2).tolist()}  z {z}", flush=True)
    K = np.array([r["k"] for r in runs])
    S = np.array([r["std"] for r in runs])
    rel = 100 * (K / truth - 1)
    scatter = np.sqrt(np.mean((K - truth) ** 2, axis=0))
    reported = np.sqrt(np.mean(S**2, axis=0))
    rows = []
    for j in range(6):
        rows.append(
            [
                f"k{j + 1}",
                f"{truth[j]:.4g}",
                f"{np.mean(K[:, j]):.5g}",
                f"{np.max(np.abs(rel[:, j])):.2f}",
                f"{100 * reported[j] / truth[j]:.2f}",
                f"{100 * scatter[j] / truth[j]:.2f}",
                f"{scatter[j] / reported[j]:.2f}",
            ]
        )
    z = (K - truth) / S
    pooled = float(np.sqrt(np.mean(z**2)))
    t_sim = np.mean([r["simulate_s"] for r in runs])
    t_run = np.mean([r["run_s"] for r in runs])
    intro = (
        f"`stiffmap simulate OUT --robot arm6 --seed S` then `stiffmap run OUT`, seeds 0..{args.seeds - 1}: "
        "20 positions, the nine load cases of the reference study (0.5, 0.2, 0.1 kg along +y, -x, -z) "
        "hung at (150, 100, -150) mm from the measured point, 3 repeats, one camera calibrated from 20 "
        "rendered views. Joint stiffnesses in N*mm/rad; errors, standard errors and scatter in % of "
        f"the truth. Pooled RMS of (estimate - truth) / reported std over the {6 * args.seeds} "
        f"estimates: {pooled:.2f} (1 when the standard errors are right). Mean time per campaign: "
        f"simulate {t_sim:.0f} s, run {t_run:.0f} s ({args.workers} workers)."
    )
    save(
        "arm_joints",
        "Six-joint arm: joint stiffnesses from simulated vision campaigns",
        ["joint", "truth", "mean estimate", "max error %", "reported std %", "scatter %", "scatter / std"],
        rows,
        intro,
    )


if __name__ == "__main__":
    main()
