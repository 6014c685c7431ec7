"""A user's own robot description on the virtual test-bed: its joint stiffnesses from simulated
vision campaigns, against the truth (issue 29).

As a user would, with a description nobody wrote for stiffmap's test-bed: the right arm of a
cluttered mobile manipulator (``tests/robots/cluttered_mm.urdf``: a planar base, wheels, a
floating caster, a torso lift, two arms, a mimic gripper, transmissions, ros2_control and
gazebo blocks), measured from its ``base_link`` (the planar joint above held):

    stiffmap simulate OUT --robot tests/robots/cluttered_mm.urdf --base base_link --tip r_tool0 \
        --tip-offset-mm 40,30,100 --configs tests/robots/cluttered_mm_configs.csv \
        --param k_theta=100,2e7,1.6e7,1.2e7,5e6,4e6,3e6 --seed S
    stiffmap run OUT

12 joint configurations (named columns: the torso lift in mm, six arm joints in degrees), the
reference study's nine load cases at the measured point (40, 30, 100 mm from the tool flange), 3 repeats,
one camera calibrated from its own rendered views; ``stiffmap run`` measures every image and
fits the seven joint stiffnesses (the lift's in N/mm) to the displacements. Per joint over the
seeds: the largest error against the truth, the mean reported standard error, the scatter.

Run:  nice -n 10 .venv/bin/python benchmarks/bench_own_urdf.py [--seeds 2] [--workers 2]
Saves benchmarks/results/own_urdf.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROBOTS = HERE.parent / "tests" / "robots"

sys.path.insert(0, str(HERE))
from _table import save  # noqa: E402

from stiffmap.campaign.store import DB_NAME, Store  # noqa: E402
from stiffmap.cli.main import main as stiffmap  # noqa: E402

TRUTH = np.array([1e2, 2e7, 1.6e7, 1.2e7, 5e6, 4e6, 3e6])  # N/mm (a soft torso lift), N*mm/rad
NAMES = ["k1 (torso lift, N/mm)", *(f"k{i} (r_joint_{i - 1})" for i in range(2, 8))]
ROBOT_ARGS = [
    "--robot", str(ROBOTS / "cluttered_mm.urdf"), "--base", "base_link", "--tip", "r_tool0",
    "--tip-offset-mm", "40,30,100", "--configs", str(ROBOTS / "cluttered_mm_configs.csv"),
    "--param", "k_theta=" + ",".join(f"{v:g}" for v in TRUTH),
]  # fmt: skip


def campaign(root: Path, seed: int, workers: int) -> dict:
    t0 = time.perf_counter()
    rc = stiffmap(
        ["simulate", str(root), *ROBOT_ARGS, "--seed", str(seed), "--workers", str(workers), "--json"]
    )
    t_sim = time.perf_counter() - t0
    if rc not in (0, None):
        raise SystemExit(f"simulate failed ({rc})")
    t0 = time.perf_counter()
    stiffmap(["run", str(root), "--workers", str(workers), "--json"])
    t_run = time.perf_counter() - t0
    with Store(root / DB_NAME) as st:
        fit = st.model_fit("stiffness")
    if fit is None or fit.status != "ok":
        raise SystemExit(f"seed {seed}: the joint fit failed: {None if fit is None else fit.error}")
    est, std = fit.params, fit.std
    names = [f"k{i}" for i in range(1, 8)]
    return {
        "k": np.array([est[n] for n in names]),
        "std": np.array([std[n] for n in names]),
        "simulate_s": t_sim,
        "run_s": t_run,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    runs = []
    for seed in range(args.seeds):
        with tempfile.TemporaryDirectory(prefix="bench_own_urdf_") as tmp:
            r = campaign(Path(tmp) / "own", seed, args.workers)
        runs.append(r)
        err = 100 * (r["k"] / TRUTH - 1)
        z = np.round((r["k"] - TRUTH) / r["std"], 2).tolist()
        print(f"seed {seed}: errors % {np.round(err, 2).tolist()}  z {z}", flush=True)
    K = np.array([r["k"] for r in runs])
    S = np.array([r["std"] for r in runs])
    rel = 100 * (K / TRUTH - 1)
    scatter = np.sqrt(np.mean((K - TRUTH) ** 2, axis=0))
    reported = np.sqrt(np.mean(S**2, axis=0))
    rows = [
        [
            NAMES[j],
            f"{TRUTH[j]:.4g}",
            f"{np.mean(K[:, j]):.5g}",
            f"{np.max(np.abs(rel[:, j])):.2f}",
            f"{100 * reported[j] / TRUTH[j]:.2f}",
            f"{100 * scatter[j] / TRUTH[j]:.2f}",
        ]
        for j in range(len(TRUTH))
    ]
    pooled = float(np.sqrt(np.mean(((K - TRUTH) / S) ** 2)))
    intro = (
        "`stiffmap simulate OUT --robot tests/robots/cluttered_mm.urdf --base base_link --tip r_tool0 "
        "--tip-offset-mm 40,30,100 --configs tests/robots/cluttered_mm_configs.csv --param k_theta=... "
        f"--seed S` then `stiffmap run OUT`, seeds 0..{args.seeds - 1}: the "
        "right arm of a cluttered mobile manipulator from its base_link (the planar joint above held), "
        "12 joint configurations (a soft torso lift, 100 N/mm, and six arm joints), the nine load "
        "cases of the reference study at the measured point, 3 repeats, one camera "
        "calibrated from 20 rendered views. Errors, standard errors and scatter in % of the truth. "
        f"Pooled RMS of (estimate - truth) / reported std over the {K.size} estimates: {pooled:.2f}. "
        f"Mean time per campaign: simulate {np.mean([r['simulate_s'] for r in runs]):.0f} s, run "
        f"{np.mean([r['run_s'] for r in runs]):.0f} s ({args.workers} workers, shared machine)."
    )
    save(
        "own_urdf",
        "A user's own URDF on the test-bed: joint stiffnesses from simulated vision campaigns",
        ["joint", "truth", "mean estimate", "max error %", "reported std %", "scatter %"],
        rows,
        intro,
    )


if __name__ == "__main__":
    main()
