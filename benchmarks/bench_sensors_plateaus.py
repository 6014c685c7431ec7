"""Plateau detection and static-error accuracy over a sweep of noise levels and step durations.

Simulated LDV/DAQ recordings (stiffmap.sim.traces) of the milling study's load sequence
0, 50, 40, 30, 20, 10, 0 kgf: LDV at 640 um/V clipped at +-8 V, 16-bit DAQ over +-10 V at
1 kHz, white noise (the swept level), linear drift of random rate (+-0.3 um/s) plus a slow
random wander (1 um RMS, periods >= 300 s), transitions of 1 s, every duration jittered
by +-25 %, static error at 490.5 N log-uniform in 0.1-2 mm (10 kgf steps of 20-400 um),
a random mirror sign, and either a load channel (dynamometer, 0.05 kgf resolution, 0.02 kgf
reading noise) or only the table of steps.

A recording counts as "found" when exactly the 7 plateaus come out, each centred on its
true plateau; "accurate" when, in addition, the static error is within 1 um + 1 % of the
truth (the issue's requirement). A second table shows the accuracy against the period of
a drift that is not linear over the recording (what zero-load plateaus cannot remove).

Run:  .venv/bin/python benchmarks/bench_sensors_plateaus.py [--quick] [--n N]
Saves benchmarks/results/sensors_plateaus.md.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
from _table import write

from stiffmap.errors import InputError
from stiffmap.sensors import SensorConfig, analyse_recording
from stiffmap.sim.traces import PAPER_STEPS_KGF, DaqChain, LoadSteps, simulate_trace

NOISES_UM = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
PLATEAUS_S = (1.0, 2.0, 5.0, 10.0)
CLAIM_MAX_NOISE_UM = 10.0  # the sweep the claim covers; 20 um is a stress level


def one(noise_um: float, plateau_s: float, channel: bool, seed, *, drift_period_s=300.0, wander_um=1.0):
    rng = np.random.default_rng(seed)
    se = float(np.exp(rng.uniform(np.log(0.1), np.log(2.0))))
    sign = int(rng.choice([-1, 1]))
    chain = DaqChain(
        sample_rate_hz=1000.0,
        noise_um=noise_um,
        drift_um_per_s=float(rng.uniform(-0.3, 0.3)),
        drift_wander_um=wander_um,
        drift_period_s=drift_period_s,
    )
    steps = LoadSteps(plateau_s=plateau_s, transition_s=1.0, load_channel=channel)
    tr = simulate_trace(static_error_mm=se, chain=chain, protocol=steps, axis_sign=sign, seed=rng)
    cfg = SensorConfig(axis_sign=sign, steps=None if channel else PAPER_STEPS_KGF)
    t0 = time.perf_counter()
    try:
        r = analyse_recording(tr.recording, cfg)
    except InputError:
        return False, False, float("nan"), time.perf_counter() - t0
    dt = time.perf_counter() - t0
    T = tr.truth.plateaus_s
    found = len(r.plateaus) == len(T) and all(
        T[i, 0] <= 0.5 * (p.t_start_s + p.t_end_s) <= T[i, 1] for i, p in enumerate(r.plateaus)
    )
    err_um = 1e3 * abs(r.static_error_mm - tr.truth.static_error_mm)
    acc = found and err_um <= 1.0 + 0.01 * 1e3 * tr.truth.static_error_mm
    return found, acc, err_um if found else float("nan"), dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20 recordings per cell instead of 100")
    ap.add_argument("--n", type=int, default=None, help="recordings per cell")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "sensors_plateaus.md"))
    args = ap.parse_args()
    n = args.n or (20 if args.quick else 100)
    t_start = time.perf_counter()
    lines = [
        "# Sensor path: plateau detection and static-error accuracy",
        "",
        f"`benchmarks/bench_sensors_plateaus.py` ({n} simulated recordings per cell; "
        f"{platform.python_implementation()} {platform.python_version()}, numpy {np.__version__}). "
        "Found: all 7 plateaus, each centred on its true plateau. Accurate: found and static error "
        "within 1 um + 1 % of the truth. Time: analysis of one recording (1 kHz).",
        "",
        "| load from | noise (um, 1 sigma) | plateau (s) | found | accurate | p95 error (um) | "
        "median time (ms) | in claim |",
        "|---|---:|---:|---:|---:|---:|---:|:---:|",
    ]
    total = {True: [0, 0, 0], False: [0, 0, 0]}
    for channel in (True, False):
        for noise in NOISES_UM:
            for plat in PLATEAUS_S:
                res = [
                    one(noise, plat, channel, [int(channel), int(noise * 10), int(plat * 10), k])
                    for k in range(n)
                ]
                found = sum(r[0] for r in res)
                acc = sum(r[1] for r in res)
                errs = np.array([r[2] for r in res if np.isfinite(r[2])])
                p95 = float(np.percentile(errs, 95)) if errs.size else float("nan")
                ms = 1e3 * float(np.median([r[3] for r in res]))
                claim = noise <= CLAIM_MAX_NOISE_UM
                if claim:
                    total[channel][0] += found
                    total[channel][1] += acc
                    total[channel][2] += n
                src = "channel" if channel else "table"
                row = (
                    f"| {src} | {noise:g} | {plat:g} | {100 * found / n:.1f} % | "
                    f"{100 * acc / n:.1f} % | {p95:.2f} | {ms:.1f} | {'yes' if claim else 'stress'} |"
                )
                lines.append(row)
                print(row, flush=True)
    lines += ["", "Over the claimed sweep (noise <= 10 um, every plateau duration):", ""]
    for channel in (True, False):
        f, a, m = total[channel]
        src = "channel" if channel else "table"
        s = (
            f"- load {src}: plateaus found in {f}/{m} = {100 * f / m:.2f} % of the "
            f"recordings, static error accurate in {a}/{m} = {100 * a / m:.2f} %"
        )
        lines.append(s)
        print(s)
    # Drift that is not linear between the zero-load plateaus.
    lines += [
        "",
        "## Drift the zero-load plateaus cannot remove",
        "",
        "Noise 2 um, 5 s plateaus, load channel; a random drift wander of 2 um RMS whose shortest "
        "period is swept (the recording lasts about 40 s). Drift removal is linear in time between "
        "the zero-load plateaus, so a wander faster than the recording leaves an error.",
        "",
        "| wander period (s) | accurate | p95 error (um) |",
        "|---:|---:|---:|",
    ]
    m2 = max(10, n // 2)
    for period in (20.0, 60.0, 300.0, 1200.0):
        res = [
            one(2.0, 5.0, True, [9, int(period), k], drift_period_s=period, wander_um=2.0) for k in range(m2)
        ]
        acc = sum(r[1] for r in res)
        errs = np.array([r[2] for r in res if np.isfinite(r[2])])
        row = f"| {period:g} | {100 * acc / m2:.1f} % | {np.percentile(errs, 95):.2f} |"
        lines.append(row)
        print(row, flush=True)
    lines += ["", f"Total run time {time.perf_counter() - t_start:.0f} s."]
    write(args.out, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
