"""A hexapod's K6 and leg stiffnesses identified from simulated 6-DOF measurements, against the truth.

The shipped 6-UPS (``robots/hexapod.toml``) with six legs of different axial stiffness is the
truth. At 16 poses (a 3 x 3 grid of positions at the home orientation, and 7 turned and
shifted poses: roll and pitch up to 8 deg, yaw up to 15 deg), nine load cases: 98.07 N
(10 kg) along +x, +y (pulleys) and -z (hung), each at three points of a bar under the platform
((0, 0, -100), (150, 0, -100), (0, 150, -100) mm, platform frame), so that the wrenches
(F, r x F) span all six directions; three repeats. The platform's deflection (u, rotation
vector) of each is K6^-1 w plus the noise of the two-camera vision rig's displacement
measurement (benchmarks/results/vision_rig.md, two cameras fused: 0.22 um per axis, the worst
axis, and 5 urad per axis).

Per seed: (1) K6 of every pose identified from its 27 measurements (identify_stiffness, 6 x 6,
the displacement covariance given), its error against the truth (relative Frobenius of
D K6 D, D = diag(1, 1, 1, 1/L, 1/L, 1/L), L the robot's size in mm: rad as L mm, so that no
block drowns the others); (2) the six leg stiffnesses fitted to all the deflections
(models.fit.fit_deflections6, the noise's standard errors given, absolute), their errors, the
standard errors the fit reports, the scatter over seeds, and the fitted model's K6 against the
truth. Before that, the model's K6 at the 16 poses against Gosselin's closed form
sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i), written here (an independent computation).

This is the identification step alone, with the rig's measured noise and loads hung at three
points (K6 itself identified); the test-bed campaign through rendered images (``stiffmap
simulate --robot hexapod`` then ``stiffmap run``, loads hung at one point, the legs fitted to
the displacements) is bench_hexapod_campaign.py.

Run:  nice -n 10 .venv/bin/python benchmarks/bench_hexapod.py [--seeds 10]
Saves benchmarks/results/hexapod.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from importlib.resources import files
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _table import markdown, write  # noqa: E402

from stiffmap.geometry import matrix_from_euler  # noqa: E402
from stiffmap.identify import identify_stiffness  # noqa: E402
from stiffmap.models.fit import fit_deflections6  # noqa: E402
from stiffmap.models.legs import LegRobot  # noqa: E402

K_TRUE = np.array([500.0, 420.0, 610.0, 380.0, 550.0, 470.0])  # N/mm, the six legs
FORCE_N = 10.0 * 9.80665
LOAD_POINTS = np.array([[0.0, 0.0, -100.0], [150.0, 0.0, -100.0], [0.0, 150.0, -100.0]])  # platform frame
SIGMA = np.array([2.2e-4, 2.2e-4, 2.2e-4, 5e-6, 5e-6, 5e-6])  # mm, rad: vision_rig.md, fused
REPEATS = 3


def poses() -> np.ndarray:
    grid = [[x, y, 300.0, 0.0, 0.0, 0.0] for y in (-40.0, 0.0, 40.0) for x in (-40.0, 0.0, 40.0)]
    turned = [
        [0.0, 0.0, 300.0, 8.0, 0.0, 0.0],
        [0.0, 0.0, 300.0, 0.0, -8.0, 0.0],
        [0.0, 0.0, 300.0, 0.0, 0.0, 15.0],
        [20.0, -15.0, 320.0, 5.0, 5.0, -10.0],
        [-25.0, 20.0, 280.0, -6.0, 4.0, 12.0],
        [30.0, 30.0, 310.0, -4.0, -6.0, 5.0],
        [-30.0, -20.0, 330.0, 7.0, -3.0, -15.0],
    ]
    P = np.array(grid + turned)
    P[:, 3:] = np.radians(P[:, 3:])
    return P


def closed_form(robot, P: np.ndarray) -> np.ndarray:
    """Gosselin's K6 from the legs' lines (base joints from the robot's description)."""
    base = np.array([d.joints[0].xyz_mm for d in robot.description])
    attach = np.array([d.attach_mm for d in robot.description])
    out = []
    for p in P:
        R = matrix_from_euler(p[3:])
        K6 = np.zeros((6, 6))
        for b, a, k in zip(base, attach, K_TRUE, strict=True):
            r = R @ a
            n = (p[:3] + r - b) / np.linalg.norm(p[:3] + r - b)
            w = np.concatenate([n, np.cross(r, n)])
            K6 += k * np.outer(w, w)
        out.append(K6)
    return np.array(out)


def wrenches(P: np.ndarray) -> np.ndarray:
    """(poses, 27, 6): the nine load cases, repeated, as wrenches at the tool point (base frame)."""
    forces = FORCE_N * np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
    out = []
    for p in P:
        R = matrix_from_euler(p[3:])
        w = [np.concatenate([F, np.cross(R @ r, F)]) for r in LOAD_POINTS for F in forces]
        out.append(np.array(w * REPEATS))
    return np.array(out)


def relative(A: np.ndarray, B: np.ndarray, L: float) -> float:
    d = np.array([1.0, 1.0, 1.0, 1 / L, 1 / L, 1 / L])
    return float(np.linalg.norm((A - B) * np.outer(d, d)) / np.linalg.norm(B * np.outer(d, d)))


def one_seed(robot, P, W, K6, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    L = robot.length_mm
    D = np.linalg.solve(K6[:, None], W[..., None])[..., 0]
    D = D + SIGMA * rng.normal(size=D.shape)
    ident, z = [], []
    for i in range(len(P)):
        f = identify_stiffness(W[i].T, D[i].T, disp_cov=np.diag(SIGMA**2))
        ident.append(relative(f.K, K6[i], L))
        z.append(((f.K - K6[i]) / f.K_std).ravel())
    names = robot.param_names()
    start = robot.with_params(**dict.fromkeys(names, 450.0))
    n = W.shape[1]
    fit = fit_deflections6(
        start,
        np.repeat(P, n, axis=0),
        W.reshape(-1, 6),
        D.reshape(-1, 6),
        params=names,
        std=np.tile(SIGMA, (len(P) * n, 1)),
        absolute_sigma=True,
    )
    K6_fit = fit.model.stiffness6(P)
    return {
        "ident": np.array(ident),
        "z": np.concatenate(z),
        "k": fit.estimate,
        "std": fit.std,
        "chi2": fit.reduced_chi2,
        "model": np.array([relative(K6_fit[i], K6[i], L) for i in range(len(P))]),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args()
    t0 = time.process_time()
    shipped = LegRobot.from_toml(files("stiffmap.models") / "robots" / "hexapod.toml")
    robot = shipped.with_params(**{f"k_leg{i + 1}": float(k) for i, k in enumerate(K_TRUE)})
    P = poses()
    K6 = robot.stiffness6(P)
    gap = max(relative(a, b, robot.length_mm) for a, b in zip(K6, closed_form(robot, P), strict=True))
    W = wrenches(P)
    runs = [one_seed(robot, P, W, K6, s) for s in range(args.seeds)]
    ident = np.concatenate([r["ident"] for r in runs])
    model = np.concatenate([r["model"] for r in runs])
    k = np.array([r["k"] for r in runs])
    std = np.array([r["std"] for r in runs])
    err = (k - K_TRUE) / K_TRUE * 100
    scatter = np.sqrt(np.mean((k - K_TRUE) ** 2, axis=0)) / K_TRUE * 100
    rstd = std.mean(axis=0) / K_TRUE * 100
    pooled = math.sqrt(float(np.mean(((k - K_TRUE) / std) ** 2)))
    rows = [
        [f"k_leg{i + 1}", f"{K_TRUE[i]:g}", f"{k[:, i].mean():.5g}", f"{np.abs(err[:, i]).max():.3f}",
         f"{rstd[i]:.3f}", f"{scatter[i]:.3f}", f"{scatter[i] / rstd[i]:.2f}"]
        for i in range(6)
    ]  # fmt: skip
    t1 = markdown(
        ["leg", "truth (N/mm)", "mean estimate", "max error %", "reported std %", "scatter %", "scatter/std"],
        rows,
    )
    t2 = markdown(
        ["K6 (relative Frobenius, rad as L mm)", "median %", "95th percentile %", "max %", "within 2 %"],
        [
            ["identified per pose (27 measurements)", *_stats(ident)],
            ["from the fitted leg stiffnesses", *_stats(model)],
        ],
    )
    chi2 = np.array([r["chi2"] for r in runs])
    z_rms = math.sqrt(float(np.mean(np.concatenate([r["z"] for r in runs]) ** 2)))
    text = f"""# Hexapod: K6 and leg stiffnesses from simulated 6-DOF measurements

{__doc__.split(chr(10) + chr(10), 1)[1].split("Run:")[0].strip()}

Model against the closed form at the 16 poses: largest relative difference {gap:.2e}
(L = {robot.length_mm:g} mm).

{args.seeds} seeds x 16 poses:

{t2}

The identified K6's entries against their propagated standard errors: RMS of (K6 - truth) / K_std
over the {36 * len(P) * args.seeds} entries {z_rms:.2f} (1 when the standard errors are right).

Leg stiffnesses ({args.seeds} seeds; errors, standard errors and scatter in % of the truth; scatter =
sqrt(mean((k - k_true)^2))). Pooled RMS of (estimate - truth) / reported std over the
{k.size} estimates: {pooled:.2f} (1 when the standard errors are right); reduced chi-square of
the fits {chi2.min():.3f} to {chi2.max():.3f}.

{t1}

CPU time {time.process_time() - t0:.1f} s.
"""
    print(text)
    write(HERE / "results" / "hexapod.md", text)


def _stats(x: np.ndarray) -> list[str]:
    x = 100 * x
    within = np.mean(x <= 2.0) * 100
    return [f"{np.median(x):.3f}", f"{np.percentile(x, 95):.3f}", f"{x.max():.3f}", f"{within:.0f} %"]


if __name__ == "__main__":
    main()
