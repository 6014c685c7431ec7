"""Benchmark: a stiffness map of 10 000 poses of each model, on one core.

Runs ``evaluate`` (inverse kinematics, singularity measures, K, det, principal stiffnesses,
reasons for bad points) and then the static error under one force, over 10 000 poses drawn
uniformly in a box around each model's workspace (so some are flagged unreachable, as in a
real map). Prints a table and saves it to ``benchmarks/results/models_map.md``.

    .venv/bin/python benchmarks/bench_models_map.py [--quick]
"""

from __future__ import annotations

import os

# One core: single-threaded BLAS and the process pinned to one CPU, before numpy loads.
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"
if hasattr(os, "sched_setaffinity"):
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _table import RESULTS, write  # noqa: E402

from stiffmap.models import PRR3, DeltaRobot  # noqa: E402

N = 10_000
CASES = [
    (
        "delta (rigid links)",
        DeltaRobot(),
        (-350.0, -350.0, -600.0),
        (350.0, 350.0, -100.0),
        (0.0, 0.0, -4.905),
    ),
    (
        "delta (arm + forearm compliance)",
        DeltaRobot(k_arm=2000.0, k_forearm=20000.0),
        (-350.0, -350.0, -600.0),
        (350.0, 350.0, -100.0),
        (0.0, 0.0, -4.905),
    ),
    ("3prr", PRR3(), (100.0, -50.0), (700.0, 500.0), (0.0, 490.5)),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 repeats instead of 15")
    args = ap.parse_args()
    repeats = 3 if args.quick else 15
    rng = np.random.default_rng(0)
    rows = []
    for label, model, lo, hi, force in CASES:
        P = rng.uniform(lo, hi, size=(N, len(lo)))
        model.evaluate(P[:10])  # warm up
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            m = model.evaluate(P)
            u = m.static_error(force)
            times.append(time.perf_counter() - t0)
        assert np.all(np.isfinite(u[m.valid])) and np.all(np.isnan(u[~m.valid]))
        rows.append((label, N, m.n_valid, min(times), float(np.median(times))))
    head = (
        f"# Model maps: {N} poses, one core\n\n"
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
        f"numpy {np.__version__}; best and median of {repeats} runs of `evaluate(points)` + "
        "`ModelMap.static_error(force)`; poses uniform in a box around the workspace.\n\n"
        "| model | poses | valid | best (s) | median (s) | under 1 s |\n|---|---:|---:|---:|---:|:---:|\n"
    )
    body = "".join(
        f"| {lab} | {n} | {v} | {b:.4f} | {md:.4f} | {'yes' if md < 1.0 else 'NO'} |\n"
        for lab, n, v, b, md in rows
    )
    text = head + body
    print(text)
    if not args.quick:
        write(RESULTS / "models_map.md", text)


if __name__ == "__main__":
    main()
