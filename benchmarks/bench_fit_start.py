"""The model fits from starting values 1e-4 .. 1e4 off: do they find the good start's answer?

A user does not know the stiffnesses before the fit. For each case the measurements are simulated
from the model itself (known stiffnesses, 0.1 % noise) and fitted from 16 starts: every fitted
parameter 1e-4, 1e-3, 1e-2, 0.1, 10, 100, 1e3 and 1e4 times its true value, and eight starts
of a random factor 10^U(-4, 4) per parameter. A start "converges" when the fit returns an
estimate within 1e-6 (relative) of the fit started at the truth; otherwise it failed (an error)
or is wrong (another estimate).

Cases: arm6 (stiffmap's six-joint arm, k1..k6 at 15 random configurations) and the KUKA KR 120
R2500 pro from its vendor xacro tree (/tmp/ros_real/kuka, see benchmarks/bench_vendor_urdf.py;
skipped without it) from 3 x 3 stiffness matrices and from static errors (three random 1 kN loads
per configuration, each read along a random direction); the hexapod (robots/hexapod.toml, six
leg stiffnesses) from K6, from 3 x 3 K, from static errors and from 6-DOF deflections; the Delta's
k_theta (48 reference positions) from K and from static errors; the 3PRR's kj + kb, kj + kb + L
(L started within 10 %) and kj + E from the milling study's static errors (models neither
linear in the stiffnesses nor in the compliances).

``--baseline SRC`` runs the same fits with the stiffmap package found in SRC (for example
``/work/main/src`` of an earlier commit, in a subprocess) for the "before" columns.

Run:  .venv/bin/python benchmarks/bench_fit_start.py [--baseline SRC]
Saves benchmarks/results/fit_start.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from importlib.resources import files
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _table import save  # noqa: E402

from stiffmap.models import PRR3, DeltaRobot  # noqa: E402
from stiffmap.models.fit import (  # noqa: E402
    fit_deflections6,
    fit_static_errors,
    fit_stiffness,
    static_error_predictions,
)
from stiffmap.models.legs import LegRobot  # noqa: E402
from stiffmap.models.presets import paper48, prr3_points22  # noqa: E402
from stiffmap.models.serial import SerialRobot  # noqa: E402

KUKA = Path("/tmp/ros_real/kuka/kuka_kr120_support/urdf/kr120r2500pro.xacro")
FACTORS = (1e-4, 1e-3, 1e-2, 1e-1, 1e1, 1e2, 1e3, 1e4)
NOISE = 1e-3


def _at(model, names, values):
    return model.with_params(**dict(zip(names, np.asarray(values, dtype=float).tolist(), strict=True)))


def _static_design(robot, P, rng, load=1000.0):
    """Three random loads per position, each read along a random direction (noisy values)."""
    PP = np.repeat(P, 3, axis=0)
    F = rng.normal(size=PP[:, :3].shape)
    F *= load / np.linalg.norm(F, axis=1, keepdims=True)
    U = rng.normal(size=F.shape)
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    y = static_error_predictions(robot, PP, F, U)
    return PP, F, U, y + NOISE * np.abs(y).mean() * rng.standard_normal(y.size)


def _noisy_K(K, rng):
    Km = K * (1 + NOISE * rng.standard_normal(K.shape))
    return 0.5 * (Km + np.swapaxes(Km, 1, 2))


def _serial_cases(label, path, offset, k, lo, hi, rng, **kw):
    Q = rng.uniform(np.radians(lo), np.radians(hi), size=(15, 6))
    Q[:, 4] *= rng.choice([-1.0, 1.0], 15)
    robot = SerialRobot.from_urdf(path, "tool0", offset, k_theta=k, configurations=Q, **kw)
    P = robot.evaluate_configurations(Q).points
    names = [f"k{i}" for i in range(1, 7)]
    Km, (PP, F, U, y) = _noisy_K(robot.stiffness(P), rng), _static_design(robot, P, rng)
    return [
        (
            f"{label}, K at 15 configurations",
            names,
            k,
            lambda s: fit_stiffness(_at(robot, names, s), P, Km, params=names),
        ),
        (
            f"{label}, static errors",
            names,
            k,
            lambda s: fit_static_errors(_at(robot, names, s), PP, F, U, y, params=names),
        ),
    ]


def _hexapod_cases(rng):
    robot = LegRobot.from_toml(files("stiffmap.models") / "robots" / "hexapod.toml")
    names = list(robot.param_names())
    k = np.array([450.0, 375.0, 550.0, 400.0, 525.0, 600.0])
    robot = _at(robot, names, k)
    m = 15
    P = np.hstack(
        [rng.uniform(-40, 40, (m, 2)), rng.uniform(280, 330, (m, 1)), rng.uniform(-0.1, 0.1, (m, 3))]
    )
    K6, K3 = _noisy_K(robot.stiffness6(P), rng), _noisy_K(robot.stiffness(P), rng)
    PP, F, U, y = _static_design(robot, P, rng, load=20.0)
    W = np.hstack([20.0 * rng.normal(size=(m, 3)), 2000.0 * rng.normal(size=(m, 3))])
    D = np.linalg.solve(robot.stiffness6(P), W[..., None])[..., 0] * (1 + NOISE * rng.standard_normal((m, 6)))
    return [
        ("hexapod legs, K6", names, k, lambda s: fit_stiffness(_at(robot, names, s), P, K6, params=names)),
        (
            "hexapod legs, 3 x 3 K",
            names,
            k,
            lambda s: fit_stiffness(_at(robot, names, s), P, K3, params=names),
        ),
        (
            "hexapod legs, static errors",
            names,
            k,
            lambda s: fit_static_errors(_at(robot, names, s), PP, F, U, y, params=names),
        ),
        (
            "hexapod legs, 6-DOF deflections",
            names,
            k,
            lambda s: fit_deflections6(_at(robot, names, s), P, W, D, params=names),
        ),
    ]


def _planar_cases(rng):
    delta, P = DeltaRobot(), paper48()
    Kd = _noisy_K(delta.stiffness(P), rng)
    Pd = np.repeat(P, 2, axis=0)
    Fd = np.tile([[0.0, 0.0, -100.0], [50.0, 0.0, 0.0]], (len(P), 1))
    Ud = Fd / np.linalg.norm(Fd, axis=1, keepdims=True)
    yd = static_error_predictions(delta, Pd, Fd, Ud) * (1 + NOISE * rng.standard_normal(len(Pd)))
    kt = ["k_theta"]
    prr = PRR3()
    P22 = prr3_points22()
    pts = np.vstack([P22, P22])
    F = np.vstack([np.tile([490.5, 0.0], (22, 1)), np.tile([0.0, 490.5], (22, 1))])
    U = F / 490.5
    y = static_error_predictions(prr, pts, F, U) * (1 + NOISE * rng.standard_normal(44))
    cases = [
        (
            "Delta k_theta, K at 48 positions",
            kt,
            [delta.k_theta],
            lambda s: fit_stiffness(_at(delta, kt, s), P, Kd, params=kt),
        ),
        (
            "Delta k_theta, static errors",
            kt,
            [delta.k_theta],
            lambda s: fit_static_errors(_at(delta, kt, s), Pd, Fd, Ud, yd, params=kt),
        ),
    ]
    for names in (("kj", "kb"), ("kj", "kb", "L"), ("kj", "E")):
        truth = [prr.params()[n] for n in names]
        cases.append(
            (
                f"3PRR {' + '.join(names)}, static errors",
                names,
                truth,
                lambda s, n=names: fit_static_errors(_at(prr, n, s), pts, F, U, y, params=n),
            )
        )
    return cases


def cases(rng):
    out = _serial_cases(
        "arm6",
        str(files("stiffmap.models") / "robots" / "arm6.urdf"),
        (30.0, -20.0, 120.0),
        np.array([2.0e9, 1.5e9, 1.0e9, 3.0e8, 2.5e8, 2.0e8]),
        [-150, -30, -60, -120, 25, -150],
        [150, 60, 20, 120, 90, 150],
        rng,
    )
    if KUKA.exists():
        out += _serial_cases(
            "KUKA KR 120 R2500 pro",
            str(KUKA),
            (10.0, -20.0, 130.0),
            np.array([8e9, 6e9, 5e9, 1.2e9, 1e9, 8e8]),
            [-150, -120, -60, -120, 25, -150],
            [150, -30, 60, 120, 100, 150],
            rng,
            package_paths=[str(KUKA.parents[2])],
        )
    return out + _hexapod_cases(rng) + _planar_cases(rng)


def starts(names, truth, rng):
    truth = np.asarray(truth, dtype=float)
    out = [truth * f for f in FACTORS] + [truth * 10 ** rng.uniform(-4, 4, truth.size) for _ in FACTORS]
    if "L" in names:  # a geometric length: started within 10 %
        for s in out:
            s[list(names).index("L")] = truth[list(names).index("L")] * rng.uniform(0.9, 1.1)
    return out


def run_all() -> list[dict]:
    rng = np.random.default_rng(20261129)
    rows = []
    for label, names, truth, fit in cases(rng):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            good = fit(np.asarray(truth, dtype=float)).estimate
            ok = failed = wrong = 0
            worst = 0.0
            t0 = time.perf_counter()
            for s in starts(names, truth, rng):
                try:
                    dev = float(np.max(np.abs(fit(s).estimate / good - 1)))
                except ValueError:
                    failed += 1
                    continue
                worst = max(worst, dev)
                ok, wrong = ok + (dev <= 1e-6), wrong + (dev > 1e-6)
            dt = time.perf_counter() - t0
        rows.append(
            {
                "case": label,
                "starts": 2 * len(FACTORS),
                "ok": ok,
                "failed": failed,
                "wrong": wrong,
                "worst": worst,
                "seconds": dt,
            }
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--baseline", help="a stiffmap src folder to run the same fits with (the 'before' columns)"
    )
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # the baseline's run
    args = ap.parse_args()
    if args.json:
        print(json.dumps(run_all()))
        return
    before = {}
    if args.baseline:
        env = {**os.environ, "PYTHONPATH": args.baseline}
        out = subprocess.run(
            [sys.executable, __file__, "--json"], env=env, capture_output=True, text=True, check=True
        )
        before = {r["case"]: r for r in json.loads(out.stdout.strip().splitlines()[-1])}
    rows = []
    for r in run_all():
        b = before.get(r["case"])
        was = "-" if b is None else f"{b['ok']} ({b['failed']} failed, {b['wrong']} wrong)"
        rows.append(
            [
                r["case"],
                r["starts"],
                was,
                f"{r['ok']} ({r['failed']} failed, {r['wrong']} wrong)",
                f"{r['worst']:.2g}",
                "-" if b is None else f"{b['seconds']:.1f}",
                f"{r['seconds']:.1f}",
            ]
        )
    notes = (
        f"Each case: 16 starts (every parameter 1e-4 .. 1e4 times the truth, then random per parameter); "
        f"'converged' when the estimate is within 1e-6 (relative) of the fit started at the truth; "
        f"0.1 % noise. A 'failed' start ended in an error: for the 3PRR with L, a start of L "
        f"about 10 % long that puts a measured pose out of reach (refused before the fit, with "
        f"the pose). Before: {args.baseline or 'not run'}."
    )
    save(
        "fit_start",
        "Model fits from far starts",
        [
            "case",
            "starts",
            "converged before",
            "converged after",
            "worst rel. difference after",
            "s before",
            "s after",
        ],
        rows,
        notes,
    )


if __name__ == "__main__":
    main()
