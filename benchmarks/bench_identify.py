"""Bias and coverage of the stiffness estimators on the reference nine-load design.

Monte Carlo: a known SPD stiffness K, the reference study's nine load cases
(Table II), displacements d = K^-1 F plus Gaussian noise of 10 % of the smallest
displacement norm (per component). For each estimator: the mean of K-hat
relative to K (bias), and for the default (compliance) estimator the fraction
of trials whose 95 % confidence interval covers each true entry.

Run: .venv/bin/python benchmarks/bench_identify.py [--trials 4000] [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _table import save

from stiffmap.identify import METHODS, identify_stiffness
from stiffmap.loads import forces_matrix, paper9


def stiffness_cases(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    yield "isotropic 5 N/mm", 5.0 * np.eye(3)
    yield "anisotropic 1.5/4/9 N/mm, rotated", Q @ np.diag([1.5, 4.0, 9.0]) @ Q.T
    yield "strongly anisotropic 0.5/5/50 N/mm", Q @ np.diag([0.5, 5.0, 50.0]) @ Q.T


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=4000)
    ap.add_argument("--quick", action="store_true", help="500 trials")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()
    trials = 500 if args.quick else args.trials
    rng = np.random.default_rng(args.seed)
    F = forces_matrix(paper9())
    rows = []
    t0 = time.perf_counter()
    for name, K in stiffness_cases(rng):
        D0 = np.linalg.solve(K, F)
        sigma = 0.1 * np.linalg.norm(D0, axis=0).min()
        est = {m: np.empty((trials, 3, 3)) for m in METHODS}
        covered = np.zeros((3, 3))
        for t in range(trials):
            D = D0 + rng.normal(scale=sigma, size=D0.shape)
            for m in METHODS:
                fit = identify_stiffness(F, D, method=m)
                est[m][t] = fit.K
                if m == "compliance":
                    lo, hi = fit.confidence_interval(0.95)
                    covered += (lo <= K) & (K <= hi)
        cov = covered / trials
        for m in METHODS:
            mean = est[m].mean(axis=0)
            nK = np.linalg.norm(K)
            rel = np.linalg.norm(mean - K) / nK
            worst_entry = np.abs(mean - K).max() / nK
            sem = est[m].std(axis=0, ddof=1).max() / np.sqrt(trials) / nK
            med = np.linalg.norm(np.median(est[m], axis=0) - K) / nK
            coverage = f"{100 * cov.mean():.1f} % ({100 * cov.min():.1f}-{100 * cov.max():.1f})"
            rows.append(
                [
                    name,
                    m,
                    f"{sigma * 1e3:.1f}",
                    f"{100 * rel:.3f} %",
                    f"{100 * worst_entry:.3f} %",
                    f"{100 * sem:.3f} %",
                    f"{100 * med:.3f} %",
                    coverage if m == "compliance" else "",
                ]
            )
    elapsed = time.perf_counter() - t0
    notes = (
        f"{trials} Monte Carlo trials per K; noise = 10 % of the smallest displacement norm, i.i.d. per "
        "component. Requirement: default (compliance) mean within 1 % of K, coverage 93-97 %.\n\n"
        "The third K (condition number 100) is outside that regime on purpose: its stiff direction moves "
        "less than the noise under these loads, so every estimator is biased there and K-hat has heavy "
        "tails (the spd fit turns a negative compliance into a near-zero one, an almost rigid direction, "
        "so its mean explodes: read the median). The remedy is larger loads along the stiff direction or "
        f"more repeats. Run time {elapsed:.0f} s."
    )
    save(
        "identify",
        "Stiffness identification: bias and 95 % coverage on the nine-load design",
        [
            "true K",
            "method",
            "noise (um, 1 sigma)",
            "|mean K-hat - K|/|K|",
            "worst entry bias / |K|",
            "MC std error / |K|",
            "|median K-hat - K|/|K|",
            "95 % CI coverage: all entries (min-max)",
        ],
        rows,
        notes=notes,
    )


if __name__ == "__main__":
    main()
