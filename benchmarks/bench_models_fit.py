"""Benchmark: accuracy of the model fits over many seeds of simulated measurement noise.

Cases (truth = the default models: 3PRR kj = 525, kb = 9800 N/mm; Delta k_theta = 2.77e5 N*mm/rad):

- kj of the 3PRR from static errors at the 22 points, a horizontal and a vertical 490.5 N load
  (50 kgf) each, the displacement read along the load, 2 % noise (44 readings);
- the same from the 8 middle-line points the milling study measured (16 readings);
- kj and kb together from the 22 points (2 % noise);
- k_theta of the Delta from stiffness matrices at the 48 reference positions, each entry with
  2 % noise of that matrix's RMS entry.

For each: mean estimate, bias, scatter of the estimates over seeds, mean reported standard
error, their ratio, coverage of the 95 % interval (estimate +- 1.96 SE), largest error, time per fit.
Saves ``benchmarks/results/models_fit.md``.

    .venv/bin/python benchmarks/bench_models_fit.py [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _table import RESULTS, write

from stiffmap.models import PRR3, DeltaRobot
from stiffmap.models.fit import fit_static_errors, fit_stiffness, static_error_predictions
from stiffmap.models.presets import PRR3_MIDDLE_LINE, paper48, prr3_points22

LOAD_N = 490.5


def _design(P):
    n = P.shape[0]
    F = np.vstack([np.tile([LOAD_N, 0.0], (n, 1)), np.tile([0.0, LOAD_N], (n, 1))])
    return np.vstack([P, P]), F, F / LOAD_N


def run_static(points, params, seeds, start):
    truth = PRR3()
    pts, F, U = _design(points)
    y0 = static_error_predictions(truth, pts, F, U)
    std = 0.02 * np.abs(y0)
    est, se, dt = [], [], []
    for s in range(seeds):
        y = y0 + std * np.random.default_rng(s).standard_normal(y0.size)
        t = time.perf_counter()
        f = fit_static_errors(PRR3().with_params(**start), pts, F, U, y, params=params, std=std)
        dt.append(time.perf_counter() - t)
        est.append(f.estimate)
        se.append(f.std)
    true = np.array([truth.params()[p] for p in params])
    return true, np.array(est), np.array(se), float(np.mean(dt))


def run_delta(seeds):
    truth = DeltaRobot()
    P = paper48()
    K = truth.stiffness(P)
    sig = np.broadcast_to(0.02 * np.sqrt(np.mean(K**2, axis=(1, 2)))[:, None, None], K.shape)
    est, se, dt = [], [], []
    for s in range(seeds):
        Km = K + sig * np.random.default_rng(s).standard_normal(K.shape)
        t = time.perf_counter()
        f = fit_stiffness(truth.with_params(k_theta=1e5), P, Km, params=("k_theta",), K_std=sig)
        dt.append(time.perf_counter() - t)
        est.append(f.estimate)
        se.append(f.std)
    return np.array([truth.k_theta]), np.array(est), np.array(se), float(np.mean(dt))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="50 seeds instead of 500")
    args = ap.parse_args()
    seeds = 50 if args.quick else 500
    P22 = prr3_points22()
    P8 = P22[np.array(PRR3_MIDDLE_LINE) - 1]
    cases = [
        ("3prr kj, 22 points x 2 loads", run_static(P22, ("kj",), seeds, {"kj": 300.0}), ("kj",)),
        ("3prr kj, 8 middle-line points x 2 loads", run_static(P8, ("kj",), seeds, {"kj": 300.0}), ("kj",)),
        (
            "3prr kj + kb, 22 points x 2 loads",
            run_static(P22, ("kj", "kb"), seeds, {"kj": 300.0, "kb": 5000.0}),
            ("kj", "kb"),
        ),
        ("delta k_theta, 48 matrices", run_delta(seeds), ("k_theta",)),
    ]
    lines = [
        f"# Model fits: {seeds} seeds of 2 % noise\n",
        "| case | parameter | truth | mean estimate | bias (%) | scatter (%) | mean SE (%) | "
        "scatter / SE | 95 % coverage | max error (%) | ms per fit |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, (true, est, se, dt), names in cases:
        for k, name in enumerate(names):
            e, s, t = est[:, k], se[:, k], true[k]
            cover = np.mean(np.abs(e - t) <= 1.96 * s)
            lines.append(
                f"| {label} | {name} | {t:g} | {np.mean(e):.6g} | {100 * (np.mean(e) / t - 1):+.3f} | "
                f"{100 * np.std(e, ddof=1) / t:.3f} | {100 * np.mean(s) / t:.3f} | "
                f"{np.std(e, ddof=1) / np.mean(s):.3f} | {100 * cover:.1f} % | "
                f"{100 * np.max(np.abs(e / t - 1)):.3f} | {1000 * dt:.1f} |"
            )
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.quick:
        write(RESULTS / "models_fit.md", text)


if __name__ == "__main__":
    main()
