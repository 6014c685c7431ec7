"""False alarms and power of the asymmetry test of an identified K (issues 26/27).

Monte Carlo: a known stiffness K, a load design, displacements d = K^-1 F plus Gaussian noise
(0.5 % of the largest displacement of each block: mm for translations, rad for rotations),
K identified with the displacements' covariance estimated from the residuals (as the
``identify`` command and the campaign runner do). For each trial the asymmetry test's p-value
by today's law (``asymmetry_p_value(K, K_cov, fit.dof, fit.K_cov_common)``: Hotelling's T^2
with the matrix-Satterthwaite effective degrees of freedom) and by the chi-square law the test
used before (``dof=None``, right only for a known covariance); the rate of p < 1 %.

Designs: the reference study's nine loads (``paper9``) twice (18 load cases); the campaign's
paper9 once and twice with the mean-reference offset (``offset=True``), and once with a
common 0.1 % scale error given (the camera calibration's share, ``common_jacobian``); 6x6:
twelve +-wrenches (5 N, 500 N mm) two and three times. Noise: equal on every axis, unequal
(standard deviations 0.3 to 3 times, geometric), and correlated between axes (0.6).

False-alarm rows: a symmetric true K. Power rows: K made asymmetric, |K - K^T| / |K| = 0.5, 2 and
5 % (equal noise; 6x6: of K scaled to a unit diagonal, its blocks being of other units).
Binomial standard error of a 1 % rate over 2000 trials: 0.22 %.

``--few-dof``: false alarms only, on 6x6 designs of few residual degrees of freedom (twelve
+-wrenches once, 6, below the q = 15 entries of K - K^T; once and two more, 8), saved apart
(``results/asymmetry_few_dof.md``).

Run: .venv/bin/python benchmarks/bench_asymmetry.py [--trials 2000] [--quick] [--few-dof]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _table import save

from stiffmap.identify import asymmetry_dof, asymmetry_p_value, identify_stiffness
from stiffmap.loads import forces_matrix, paper9
from stiffmap.stiffness import stiffness_indices

LEVEL = 0.01
#: The relative asymmetries |K - K^T| / |K| of the power rows.
POWER_AT = (0.005, 0.02, 0.05)
_WRENCH = np.diag([5.0, 5.0, 5.0, 500.0, 500.0, 500.0])  # N, N mm


def _spd(rng, m: int, lo: float, hi: float) -> np.ndarray:
    Q, _ = np.linalg.qr(rng.normal(size=(m, m)))
    return Q @ np.diag(np.geomspace(lo, hi, m)) @ Q.T


def designs():
    """(name, F, offset, common scale error's standard deviation or 0)."""
    F9 = forces_matrix(paper9())
    W12 = np.hstack([_WRENCH, -_WRENCH])
    yield "3x3 paper9 x2", np.tile(F9, 2), False, 0.0
    yield "3x3 paper9 x1, offset (campaign)", F9, True, 0.0
    yield "3x3 paper9 x1, offset, 0.1 % scale", F9, True, 1e-3
    yield "3x3 paper9 x2, offset (campaign)", np.tile(F9, 2), True, 0.0
    yield "6x6 12 wrenches x2", np.tile(W12, 2), False, 0.0
    yield "6x6 12 wrenches x3", np.tile(W12, 3), False, 0.0


def few_dof_designs():
    """6x6 designs of few residual degrees of freedom (name, F, offset, scale error 0)."""
    W12 = np.hstack([_WRENCH, -_WRENCH])
    yield "6x6 12 wrenches x1", W12, False, 0.0
    yield "6x6 12 wrenches x1 + 2", np.hstack([W12, W12[:, :2]]), False, 0.0


def true_stiffness(rng, m: int) -> np.ndarray:
    if m == 3:
        return _spd(rng, 3, 2.0, 20.0)  # N/mm
    Z = np.zeros((3, 3))
    return np.block([[_spd(rng, 3, 2.0, 20.0), Z], [Z, _spd(rng, 3, 2e4, 2e5)]])  # N/mm, N mm/rad


def asymmetric(K: np.ndarray, target: float, rng) -> np.ndarray:
    """K plus an antisymmetric part of relative size ``target``. 3x3: symmetric K plus s N, N
    antisymmetric of unit norm: |K - K^T| / |K + s N| = 2 s / sqrt(|K|^2 + s^2) (the parts are
    orthogonal) equals ``target`` for s = target |K| / sqrt(4 - target^2). 6x6 (mixed units):
    the same on the scaled Kd = S^-1/2 K S^-1/2, S = diag(K), then K = S^1/2 Kd S^1/2."""
    sd = np.sqrt(np.diag(K)) if K.shape[0] == 6 else np.ones(K.shape[0])
    Kd = K / np.outer(sd, sd)
    N = rng.normal(size=K.shape)
    N = (N - N.T) / np.linalg.norm(N - N.T)
    Ka = Kd + target * np.linalg.norm(Kd) / np.sqrt(4 - target**2) * N
    assert abs(stiffness_indices(Ka).asymmetry - target) < 1e-9
    return Ka * np.outer(sd, sd)


def noise_root(D0: np.ndarray, kind: str) -> np.ndarray:
    """L with the noise L z, z standard normal: 0.5 % of each block's largest displacement."""
    m = D0.shape[0]
    base = np.concatenate([np.full(3, 0.005 * np.abs(D0[b : b + 3]).max()) for b in range(0, m, 3)])
    if kind == "equal":
        return np.diag(base)
    if kind == "unequal":
        return np.diag(base * np.geomspace(0.3, 3.0, m))
    R = np.full((m, m), 0.6) + 0.4 * np.eye(m)
    return np.linalg.cholesky(np.diag(base) @ R @ np.diag(base))


def p_values(rng, K, F, offset, scale_sd, L, trials):
    """p-values by today's law and by the chi-square law over the trials; the residual dof and
    the median effective dof (of the first 100 trials)."""
    D0 = np.linalg.solve(K, F)
    G = D0.T[:, :, None] if scale_sd else None  # d d_i / d scale = d_i (n, m, 1)
    common = {"common_jacobian": G, "common_cov": np.array([[scale_sd**2]])} if scale_sd else {}
    p = np.empty((trials, 2))
    nu_e = []
    for t in range(trials):
        e = rng.normal(size=D0.shape)
        D = (D0 * (1 + scale_sd * rng.normal()) if scale_sd else D0) + L @ e
        fit = identify_stiffness(F, D, offset=offset, **common)
        p[t, 0] = asymmetry_p_value(fit.K, fit.K_cov, fit.dof, fit.K_cov_common)
        p[t, 1] = asymmetry_p_value(fit.K, fit.K_cov)  # the chi-square law
        if t < 100:
            nu_e.append(asymmetry_dof(fit.K, fit.K_cov, fit.dof, fit.K_cov_common))
    return p, fit.dof, float(np.median(nu_e))


def _pct(x: float) -> str:
    return f"{100 * x:.2f} %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=2000)
    ap.add_argument("--quick", action="store_true", help="300 trials")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--few-dof", action="store_true", help="false alarms of 6x6 designs of 6 and 8 dof")
    args = ap.parse_args()
    if args.few_dof:
        few_dof(args)
        return
    trials = 300 if args.quick else args.trials
    t0 = time.perf_counter()
    rows = _rows(designs(), trials, np.random.default_rng(args.seed), power=True)
    elapsed = time.perf_counter() - t0
    save(
        "asymmetry",
        "Asymmetry test: false alarms at 1 % and power",
        [
            "design",
            "residual dof",
            "effective dof (median)",
            "true K",
            "noise",
            "p < 1 %: Hotelling, effective dof",
            "chi-square (before)",
            "chi-square at its real 1 %",
        ],
        rows,
        notes=(
            f"{trials} trials per row, seed {args.seed}, {elapsed:.0f} s. Symmetric rows: the "
            "false-alarm rate (nominal 1 %; binomial standard error "
            f"{100 * np.sqrt(0.01 * 0.99 / trials):.2f} %). Asymmetric rows: the power; the last "
            "column is the chi-square law's power at its real 1 % level (its p-value below the 1 % "
            "quantile of its p-values on the symmetric K, equal noise, of the same design): what a "
            "corrected chi-square test would detect."
        ),
    )


def _rows(design_list, trials: int, rng, power: bool) -> list[list]:
    """One row per design and case: the symmetric K under three noises, and (``power``) K made
    asymmetric by 0.5, 2 and 5 % under equal noise."""
    rows = []
    for name, F, offset, scale_sd in design_list:
        K = true_stiffness(rng, F.shape[0])
        D0 = np.linalg.solve(K, F)
        cases = [("symmetric", K, kind) for kind in ("equal", "unequal", "correlated")]
        if power:
            cases += [(f"asymmetric {100 * t:g} %", asymmetric(K, t, rng), "equal") for t in POWER_AT]
        for truth, Kt, kind in cases:
            p, dof, nu_e = p_values(rng, Kt, F, offset, scale_sd, noise_root(D0, kind), trials)
            if truth == "symmetric" and kind == "equal":
                real = np.quantile(p[:, 1], LEVEL)  # the chi-square p-value at its real 1 % level
            rate = (p < LEVEL).mean(axis=0)
            at_level = "" if truth == "symmetric" else _pct(np.mean(p[:, 1] < real))
            rows.append([name, dof, f"{nu_e:.1f}", truth, kind, _pct(rate[0]), _pct(rate[1]), at_level])
            print(" | ".join(str(c) for c in rows[-1]), flush=True)
    return rows


def few_dof(args) -> None:
    """False alarms of a symmetric 6x6 K identified with few residual degrees of freedom."""
    trials = 300 if args.quick else args.trials
    t0 = time.perf_counter()
    rows = [r[:-1] for r in _rows(few_dof_designs(), trials, np.random.default_rng(args.seed), power=False)]
    save(
        "asymmetry_few_dof",
        "Asymmetry test: false alarms at 1 % of a 6x6 K with few residual degrees of freedom",
        ["design", "residual dof", "effective dof (median)", "true K", "noise", "p < 1 %: Hotelling", "chi2"],
        rows,
        notes=(
            f"{trials} trials per row, seed {args.seed}, {time.perf_counter() - t0:.0f} s. A symmetric "
            "K (nominal 1 %; binomial standard error "
            f"{100 * np.sqrt(0.01 * 0.99 / trials):.2f} %)."
        ),
    )


if __name__ == "__main__":
    main()
