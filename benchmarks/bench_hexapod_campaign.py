"""The test-bed hexapod's leg stiffnesses and K6 from simulated vision campaigns, against the truth.

As a user would: ``stiffmap simulate OUT --robot hexapod --seed S --select ... --repeats R``
(the shipped 6-UPS on spring legs of six different stiffnesses, kinds.parallel.HEXAPOD_TESTBED_K;
the platform level; the reference study's nine load cases hung 100 mm below the platform's
centre, so that they turn it; one camera calibrated from its own rendered views) then
``stiffmap run OUT``, which measures every image (6-DOF displacements with their 6 x 6
covariances) and identifies K at each position. The six leg stiffnesses are then fitted to the
measured displacements (campaign.platform.fit_platform) two ways, side by side on the same
campaigns:

- before (the fit until issue 30): each displacement's components weighed by the diagonal of
  its covariance alone, the fit's covariance scaled by its reduced chi-square;
- after (what ``stiffmap run`` does now): whitened by the full 6 x 6 covariance plus a shared
  extra noise estimated from the residuals, the standard errors those of the inflated
  covariances.

Per seed and way: each leg's error and reported standard error; the fitted model's K6 at each
position against the true K6 (relative Frobenius of D K6 D, D = diag(1, 1, 1, 1/L, 1/L, 1/L), L
the robot's size: rad as L mm); and each position's measured K against truth.json's.

``--cache DIR`` keeps the simulated and measured campaigns in DIR (one folder per seed, select
and repeats) and reuses them: a re-run only re-fits (seconds instead of minutes per campaign).

Run:  nice -n 10 .venv/bin/python benchmarks/bench_hexapod_campaign.py [--seeds 3] [--select 1,5,9,10,14,18]
      [--cache /tmp/hexcache] [--turned]
Saves benchmarks/results/hexapod_campaign.md (hexapod_campaign_turned.md with --turned).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _table import save  # noqa: E402

from stiffmap.campaign.platform import fit_platform  # noqa: E402
from stiffmap.campaign.positions import campaign_poses  # noqa: E402
from stiffmap.campaign.robot import campaign_model, fitted_names  # noqa: E402
from stiffmap.campaign.spec import load_spec  # noqa: E402
from stiffmap.campaign.store import DB_NAME, Store  # noqa: E402
from stiffmap.cli.main import main as stiffmap  # noqa: E402
from stiffmap.kinds.parallel import HEXAPOD_TESTBED_K, HEXAPOD_TESTBED_POSITIONS  # noqa: E402

NAMES = [f"k_leg{i}" for i in range(1, 7)]
#: The two fits compared: (label, fit_platform keywords).
WAYS = (("before", {"correlated": False, "extra_noise": False}), ("after", {}))
COLUMNS = ("max error %", "reported std %", "scatter %", "scatter / std")


def turned_poses(path: Path) -> Path:
    """The test-bed's 18 positions with the platform turned (``--turned``): roll and pitch in
    {-10, -5, 0, 5, 10} degrees, a different pair at each position, yaw 0 (a CSV for --positions)."""
    rows = ["x,y,z,roll_deg,pitch_deg,yaw_deg"]
    for k, p in enumerate(HEXAPOD_TESTBED_POSITIONS.split(";")):
        rows.append(f"{p},{((7 * k) % 5 - 2) * 5},{((3 * k + 1) % 5 - 2) * 5},0")
    path.write_text("\n".join(rows) + "\n")
    return path


def _pose(p: dict) -> list[float]:
    """truth.json's pose of a position: x, y, z mm and roll, pitch, yaw rad (level when not turned)."""
    return [*p["position"], *np.radians(p.get("orientation_deg", [0.0, 0.0, 0.0]))]


def measured_campaign(root: Path, seed: int, select: str, repeats: int, workers: int, positions=None) -> dict:
    """Simulate and measure the campaign at ``root`` unless its markers say it was done
    (``simulated.ok``, ``measured.ok`` beside it); the seconds each step took (0 when reused).
    ``positions``: a --positions CSV (the platform turned)."""
    times = {"simulate_s": 0.0, "run_s": 0.0}
    done_sim, done_run = root.parent / "simulated.ok", root.parent / "measured.ok"
    if not done_sim.exists():
        t0 = time.perf_counter()
        args = ["simulate", str(root), "--robot", "hexapod", "--seed", str(seed), "--select", select]
        if positions is not None:
            args += ["--positions", str(positions)]
        rc = stiffmap([*args, "--repeats", str(repeats), "--workers", str(workers), "--json", "--force"])
        if rc not in (0, None):
            raise SystemExit(f"simulate failed ({rc})")
        times["simulate_s"] = time.perf_counter() - t0
        done_sim.touch()
        done_run.unlink(missing_ok=True)
    if not done_run.exists():
        t0 = time.perf_counter()
        stiffmap(["run", str(root), "--workers", str(workers), "--json"])  # warnings: rc 1
        times["run_s"] = time.perf_counter() - t0
        done_run.touch()
    return times


def fit_ways(root: Path) -> dict:
    """The legs fitted both ways (:data:`WAYS`) to the campaign's measured displacements."""
    spec = load_spec(root / "campaign.toml")
    model = campaign_model(spec, root)
    with Store(root / DB_NAME) as st:
        rows = st.stiffness_rows()
        disp = st.displacement_rows(only_ok=True)
    loads = spec.loads.resolve(spec.g)
    at = {r.position: i for i, r in enumerate(rows)}
    keep = [d for d in disp if d.position in at and d.load <= len(loads)]
    args = (
        model,
        campaign_poses(spec, [[r.x, r.y, r.z] for r in rows], [r.position for r in rows]),
        [at[d.position] for d in keep],
        [loads[d.load - 1].force for d in keep],
        np.asarray(spec.loads.point_mm or (0.0, 0.0, 0.0), dtype=float),
        np.array([d.d for d in keep], dtype=float),
        np.array([d.cov for d in keep], dtype=float),
        fitted_names(spec, model),
    )
    return {way: fit_platform(*args, **kw) for way, kw in WAYS}


def evaluate(root: Path) -> dict:
    """Per way: legs, standard errors, K6 errors; the measured K's errors; the extra noise."""
    truth = json.loads((root / "truth.json").read_text())
    Kt = {p["index"]: np.array(p["K"]) for p in truth["positions"]}
    K6t = {p["index"]: np.array(p["K_tcp"]) for p in truth["positions"]}
    poses = {p["index"]: _pose(p) for p in truth["positions"]}
    with Store(root / DB_NAME) as st:
        rows = [r for r in st.stiffness_rows() if r.status == "ok"]
    fits = fit_ways(root)
    rel = [np.linalg.norm(np.array(r.K) - Kt[r.position]) / np.linalg.norm(Kt[r.position]) for r in rows]
    out: dict = {"K": np.array(rel)}
    for way, fit in fits.items():
        model = fit.model
        d = np.array([1.0, 1.0, 1.0, *(3 * [1.0 / model.length_mm])])
        D = np.outer(d, d)
        K6 = model.stiffness6(np.array([poses[r.position] for r in rows]))
        T = np.array([K6t[r.position] for r in rows])
        k6 = np.linalg.norm((K6 - T) * D, axis=(1, 2)) / np.linalg.norm(T * D, axis=(1, 2))
        out[way] = {
            "k": np.array([fit.values[n] for n in NAMES]),
            "std": np.array([fit.std_values[n] for n in NAMES]),
            "K6": np.array(k6),
            "chi2": fit.reduced_chi2,
        }
    out["extra_std"] = fits["after"].extra_std
    return out


def summary(runs: list[dict], way: str, truth: np.ndarray) -> dict:
    K = np.array([r[way]["k"] for r in runs])
    S = np.array([r[way]["std"] for r in runs])
    k6 = 100 * np.concatenate([r[way]["K6"] for r in runs])
    return {
        "rel": 100 * (K / truth - 1),
        "mean": K.mean(axis=0),
        "reported": np.sqrt(np.mean(S**2, axis=0)),
        "scatter": np.sqrt(np.mean((K - truth) ** 2, axis=0)),
        "pooled": float(np.sqrt(np.mean(((K - truth) / S) ** 2))),
        "k6_median": float(np.median(k6)),
        "k6_worst": float(k6.max()),
    }


def table_rows(b: dict, a: dict, truth: np.ndarray) -> list[list[str]]:
    rows = []
    for j in range(6):
        cells = [NAMES[j], f"{truth[j]:g}"]
        for s in (b, a):
            rep, sca = s["reported"][j], s["scatter"][j]
            cells += [f"{np.max(np.abs(s['rel'][:, j])):.3f}", f"{100 * rep / truth[j]:.3f}"]
            cells += [f"{100 * sca / truth[j]:.3f}", f"{sca / rep:.2f}"]
        rows.append(cells)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--select", default="1,5,9,10,14,18")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, help="keep the simulated campaigns here and reuse them")
    ap.add_argument("--turned", action="store_true", help="the platform turned (roll, pitch up to 10 deg)")
    args = ap.parse_args()
    truth = np.array(HEXAPOD_TESTBED_K)
    runs, times = [], []
    tmp = None if args.cache else tempfile.TemporaryDirectory(prefix="bench_hexapod_")
    base = args.cache or Path(tmp.name)
    for seed in range(args.seeds):
        tag = "_turned" if args.turned else ""
        root = base / f"s{seed}_{args.select.replace(',', '-')}_r{args.repeats}{tag}" / "hexapod"
        root.parent.mkdir(parents=True, exist_ok=True)
        poses = turned_poses(root.parent / "poses.csv") if args.turned else None
        times.append(measured_campaign(root, seed, args.select, args.repeats, args.workers, poses))
        runs.append(evaluate(root))
        err = {w: np.round(100 * (runs[-1][w]["k"] / truth - 1), 3).tolist() for w, _ in WAYS}
        print(f"seed {seed}: leg errors % before {err['before']}, after {err['after']}", flush=True)
    if tmp is not None:
        tmp.cleanup()
    b, a = summary(runs, "before", truth), summary(runs, "after", truth)
    save(
        "hexapod_campaign_turned" if args.turned else "hexapod_campaign",
        "Hexapod: leg stiffnesses and K6 from simulated vision campaigns"
        + (", the platform turned" if args.turned else ""),
        [
            "leg",
            "truth",
            *[
                f"{w}: {c}"
                for w in ("before", "after")
                for c in ("max error %", "reported std %", "scatter %", "scatter / std")
            ],
        ],  # fmt: skip
        table_rows(b, a, truth),
        intro(args, runs, times, b, a),
    )


def intro(args, runs: list[dict], times: list[dict], b: dict, a: dict) -> str:
    n = len(runs)
    k_meas = 100 * np.concatenate([r["K"] for r in runs])
    xs = np.mean([r["extra_std"] for r in runs], axis=0)
    chi2 = {w: ", ".join(f"{r[w]['chi2']:.2f}" for r in runs) for w, _ in WAYS}
    sim = [t["simulate_s"] for t in times if t["simulate_s"] > 0]
    run = [t["run_s"] for t in times if t["run_s"] > 0]
    timing = (
        f"Mean time per campaign simulated here: simulate {np.mean(sim):.0f} s, run {np.mean(run):.0f} s "
        f"({args.workers} workers, machine shared)."
        if sim
        else "The campaigns were reused from --cache (simulated and measured before; only the fits ran here)."
    )
    return (
        f"`stiffmap simulate OUT --robot hexapod --seed S --select {args.select} --repeats {args.repeats}` "
        f"then `stiffmap run OUT`, seeds 0..{n - 1}: {len(args.select.split(','))} positions of the "
        "test-bed's 18 (x, y in {-40, 0, 40} mm, z 280 and 320 mm; "
        + (
            "`--turned`: `--positions POSES.csv`, the platform turned at each, roll and pitch in "
            "{-10, -5, 0, 5, 10} deg, turned_poses), the reference "
            if args.turned
            else "the platform level), the reference "
        )
        + "study's nine load cases (0.5, 0.2, 0.1 kg along +y, -x, -z) hung 100 mm below the platform's "
        "centre, one camera calibrated from 20 rendered views. The six legs fitted to the same measured "
        "displacements two ways: **before** (each component weighed by the diagonal of its covariance "
        "alone, covariance scaled by chi2/dof: the fit until issue 30) and **after** (whitened by the full "
        "6 x 6 covariance plus a shared 6 x 6 extra noise estimated from the residuals, standard errors "
        "those of the inflated covariances: `stiffmap run` now). Legs in N/mm; errors, standard errors "
        "and scatter in % of the truth (scatter = sqrt(mean((k - k_true)^2)) over the seeds).\n\n"
        f"Pooled RMS of (estimate - truth) / reported std over the {6 * n} estimates (1 when the "
        f"standard errors are right; {6 * n} estimates put about +-{1 / np.sqrt(2 * 6 * n):.2f} on it): "
        f"before **{b['pooled']:.2f}**, after **{a['pooled']:.2f}**. The fitted model's K6 at each "
        f"position against the true K6 (relative Frobenius, rad as L mm; target 2 %): before median "
        f"{b['k6_median']:.3f} %, worst {b['k6_worst']:.3f} %; after median {a['k6_median']:.3f} %, worst "
        f"{a['k6_worst']:.3f} %. Legs worst error: before {np.abs(b['rel']).max():.3f} %, after "
        f"{np.abs(a['rel']).max():.3f} % (target 1 %). Reduced chi-square of the fit per seed: before "
        f"{chi2['before']}; after {chi2['after']}. The extra noise estimated (std per axis, mean over the "
        f"seeds): u {', '.join(f'{1e3 * v:.2f}' for v in xs[:3])} um, rotation "
        f"{', '.join(f'{1e3 * v:.4f}' for v in xs[3:])} mrad. Measured K per position (3 x 3, the hung "
        f"forces', the same both ways) against truth.json: median {np.median(k_meas):.2f} %, worst "
        f"{k_meas.max():.2f} %. {timing}"
    )


if __name__ == "__main__":
    main()
