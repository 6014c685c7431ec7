"""A user's own legs TOML on the virtual test-bed: K6 and the leg stiffnesses recovered, loads scaled or not.

As a user would: ``stiffmap simulate OUT --robot my_hexapod.toml --seed S --select ... --repeats R``
then ``stiffmap run OUT``. The robot is a 6-UPS of our own (``tests/helpers/own_hexapod.py``,
shared with ``tests/test_simulate_own_legs.py``: base joints on a 220 mm circle, platform joints
on a 120 mm circle, home height 260 mm) on stiff legs of six different stiffnesses (350-540 N/mm,
the order of the shipped hexapod.toml's 500 N/mm), seen by one camera calibrated from its own
rendered views; its default positions (a 3 x 3 x 2 grid 35 mm apart about its home), loads
hung 100 mm below the platform's centre. Three load cases:

- ``scaled``: ``--loads paper9`` as ``simulate`` takes it for a robot of one's own: paper9's
  largest displacement of the tool point (0.025 mm here) is outside 0.5-4 mm, so its masses
  are scaled (x 50: about 1.2 mm; campaign.simulate.OWN_DISPLACEMENT_RANGE_MM);
- ``paper9``: the reference study's forces themselves, as a CSV file (kept as given, with a
  warning): what a user would get without the rule;
- ``paper9x10``: those forces times 10, as a CSV file (0.25 mm: about the lower end of the range).

Per seed and case: each leg's error and reported standard error (``stiffmap run``'s fit,
``campaign.platform.fit_platform``), and the fitted model's K6 at each position against the true
K6 (relative Frobenius of D K6 D, D = diag(1, 1, 1, 1/L, 1/L, 1/L), L the robot's size).

Run:  nice -n 10 .venv/bin/python benchmarks/bench_own_legs.py [--seeds 3] [--select 1,5,9,10,14,18]
      [--cases scaled,paper9x10,paper9] [--cache /tmp/ownlegs]
Saves benchmarks/results/own_legs.md.

``--rps3``: instead, the shipped ``3rps.toml`` with ``--param k_leg2=400,k_bend3=100`` (a 3-RPS:
z, roll, pitch; its default grid in those, x, y, yaw solved; ``--rps3-select`` of its positions,
paper9 scaled by ``simulate``): per seed the six springs' errors and reported std, and the fitted
model's K6 at all 18 default poses against the true K6. Saves benchmarks/results/own_legs_3rps.md.
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
sys.path.insert(0, str(HERE.parent / "tests"))
from _table import save  # noqa: E402
from bench_hexapod_campaign import evaluate  # noqa: E402
from helpers.own_hexapod import NAMES, OWN_K, write_own_hexapod  # noqa: E402

from stiffmap.campaign.store import DB_NAME, Store  # noqa: E402
from stiffmap.cli.main import main as stiffmap  # noqa: E402
from stiffmap.kinds.parallel import BUILTIN_LEGS, legs_default_poses  # noqa: E402
from stiffmap.loads import paper9  # noqa: E402
from stiffmap.models.legs import LegRobot  # noqa: E402
from stiffmap.models.mobility import platform_mobility  # noqa: E402
from stiffmap.units import G_REFERENCE_PAPER  # noqa: E402


def write_paper9(path: Path, factor: float = 1.0) -> Path:
    """paper9's forces (g = 9.81) times ``factor`` as a --loads CSV file: kept as given for a robot
    of one's own."""
    rows = ["fx,fy,fz,label"] + [
        ",".join(f"{factor * v:.17g}" for v in ld.force)
        + f",{ld.label}"
        + (f" x {factor:g}" if factor != 1 else "")
        for ld in paper9(g=G_REFERENCE_PAPER)
    ]
    path.write_text("\n".join(rows) + "\n")
    return path


def campaign(root: Path, robot: Path, loads: str, seed: int, args, extra=()) -> dict:
    """Simulate and run the campaign at ``root`` unless done (markers beside it); its summary and times."""
    out = {"simulate_s": 0.0, "run_s": 0.0}
    sim_ok, run_ok = root.parent / "simulated.json", root.parent / "measured.ok"
    if not sim_ok.exists():
        t0 = time.perf_counter()
        cmd = ["simulate", str(root), "--robot", str(robot), "--loads", loads, "--seed", str(seed)]
        cmd += ["--repeats", str(args.repeats), "--workers", str(args.workers), *extra]
        cmd += ["--select", args.select] if args.select else []
        rc = stiffmap([*cmd, "--json", "--force"])
        if rc not in (0, 1, None):  # 1: the warning of the unscaled loads
            raise SystemExit(f"simulate failed ({rc})")
        out["simulate_s"] = time.perf_counter() - t0
        sim_ok.write_text(json.dumps({"seconds": out["simulate_s"]}))
        run_ok.unlink(missing_ok=True)
    if not run_ok.exists():
        t0 = time.perf_counter()
        stiffmap(["run", str(root), "--workers", str(args.workers), "--json"])  # warnings: rc 1
        out["run_s"] = time.perf_counter() - t0
        run_ok.touch()
    truth = json.loads((root / "truth.json").read_text())
    out["forces"] = np.array([ld["force_n"] for ld in truth["loads"]])
    return out


def summary(runs: list[dict], truth: np.ndarray) -> dict:
    K = np.array([r["after"]["k"] for r in runs])
    S = np.array([r["after"]["std"] for r in runs])
    k6 = 100 * np.concatenate([r["after"]["K6"] for r in runs])
    return {
        "rel": 100 * (K / truth - 1),
        "reported": np.sqrt(np.mean(S**2, axis=0)),
        "scatter": np.sqrt(np.mean((K - truth) ** 2, axis=0)),
        "pooled": float(np.sqrt(np.mean(((K - truth) / S) ** 2))),
        "k6_median": float(np.median(k6)),
        "k6_worst": float(k6.max()),
        "K_median": float(100 * np.median(np.concatenate([r["K"] for r in runs]))),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--select", default="1,5,9,10,14,18")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--cases", default="scaled,paper9x10,paper9")
    ap.add_argument("--cache", type=Path, help="keep the simulated campaigns here and reuse them")
    ap.add_argument("--rps3", action="store_true", help="the shipped 3-RPS instead (module docstring)")
    ap.add_argument("--rps3-select", default="", help="positions of its 18 (default: all)")
    args = ap.parse_args()
    if args.rps3:
        rps3(args)
        return
    tmp = None if args.cache else tempfile.TemporaryDirectory(prefix="bench_own_legs_")
    base = args.cache or Path(tmp.name)
    base.mkdir(parents=True, exist_ok=True)
    robot = write_own_hexapod(base / "my_hexapod.toml")
    load_files = {"scaled": "paper9", "paper9": str(write_paper9(base / "paper9.csv"))}
    load_files["paper9x10"] = str(write_paper9(base / "paper9x10.csv", 10.0))
    truth = np.array(OWN_K)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    results, times, forces = {}, [], {}
    for case in cases:
        runs = []
        for seed in range(args.seeds):
            root = base / f"{case}_s{seed}_{args.select.replace(',', '-')}_r{args.repeats}" / "own"
            root.parent.mkdir(parents=True, exist_ok=True)
            t = campaign(root, robot, load_files[case], seed, args)
            times.append(t)
            forces[case] = t["forces"]
            runs.append(evaluate(root))
            err = np.round(100 * (runs[-1]["after"]["k"] / truth - 1), 3).tolist()
            k6 = 100 * runs[-1]["after"]["K6"]
            print(f"{case} seed {seed}: leg errors % {err}, K6 worst {k6.max():.3f} %", flush=True)
        results[case] = summary(runs, truth)
    if tmp is not None:
        tmp.cleanup()
    rows = []
    for j, name in enumerate(NAMES):
        cells = [name, f"{truth[j]:g}"]
        for case in cases:
            s = results[case]
            cells += [f"{np.max(np.abs(s['rel'][:, j])):.3f}", f"{100 * s['reported'][j] / truth[j]:.3f}"]
            cells += [f"{100 * s['scatter'][j] / truth[j]:.3f}"]
        rows.append(cells)
    columns = ["leg", "truth N/mm"] + [
        f"{c}: {h}" for c in cases for h in ("max error %", "reported std %", "scatter %")
    ]
    title = "A legs TOML of one's own: leg stiffnesses and K6 from simulated campaigns"
    save("own_legs", title, columns, rows, intro(args, cases, results, forces, times))


RPS3_PARAMS = {"k_leg2": 400.0, "k_bend3": 100.0}


def rps3(args) -> None:
    """The 3-RPS: ``simulate --robot 3rps.toml --param k_leg2=400,k_bend3=100`` then ``run``, per seed."""
    tmp = None if args.cache else tempfile.TemporaryDirectory(prefix="bench_own_legs_")
    base = args.cache or Path(tmp.name)
    robot = Path(BUILTIN_LEGS["3rps"])
    model = LegRobot.from_toml(robot)
    model = model.with_params(**{**model.params(), **RPS3_PARAMS})
    truth = model.params()
    names = list(truth)
    poses, _ = legs_default_poses(model, platform_mobility(model))  # the 18 default poses
    K6_true = model.stiffness6(poses)
    d = np.r_[np.ones(3), np.full(3, 1.0 / model.length_mm)]
    D = np.outer(d, d)
    sel = replace_select(args)
    est, std, k6, times = [], [], [], []
    for seed in range(args.seeds):
        root = base / f"rps3_s{seed}_{sel.select.replace(',', '-') or 'all'}_r{sel.repeats}" / "own"
        root.parent.mkdir(parents=True, exist_ok=True)
        params = ",".join(f"{k}={v:g}" for k, v in RPS3_PARAMS.items())
        times.append(campaign(root, robot, "paper9", seed, sel, ("--param", params)))
        with Store(root / DB_NAME) as st:
            fit = st.model_fit("stiffness")
        est.append([fit.params[n] for n in names])
        std.append([fit.std[n] for n in names])
        K6 = model.with_params(**fit.params).stiffness6(poses)
        k6.append(np.linalg.norm((K6 - K6_true) * D, axis=(1, 2)) / np.linalg.norm(K6_true * D, axis=(1, 2)))
        err = np.round(100 * (np.array(est[-1]) / [truth[n] for n in names] - 1), 3).tolist()
        print(f"3rps seed {seed}: spring errors % {err}, K6 worst {100 * k6[-1].max():.3f} %", flush=True)
    if tmp is not None:
        tmp.cleanup()
    T = np.array([truth[n] for n in names])
    E, S = np.array(est), np.array(std)
    rows = [
        [n, f"{T[j]:g}", f"{100 * np.abs(E[:, j] / T[j] - 1).max():.3f}",
         f"{100 * np.sqrt(np.mean(S[:, j] ** 2)) / T[j]:.3f}",
         f"{100 * np.sqrt(np.mean((E[:, j] - T[j]) ** 2)) / T[j]:.3f}"]
        for j, n in enumerate(names)
    ]  # fmt: skip
    k6 = 100 * np.array(k6)
    sim = [t["simulate_s"] for t in times if t["simulate_s"] > 0]
    intro = (
        f"`stiffmap simulate OUT --robot 3rps.toml --param k_leg2=400,k_bend3=100 --seed S "
        f"{'--select ' + sel.select if sel.select else '(its 18 default poses)'} --repeats {sel.repeats}` "
        f"then `stiffmap run OUT`, seeds 0..{args.seeds - 1}: the "
        "shipped 3-RPS (z, roll, pitch; its default grid roll and pitch -8, 0, 8 deg, z 235 and 265 mm, "
        "x, y and yaw solved), paper9 scaled by `simulate`, hung 100 mm below the platform's centre, one "
        "camera calibrated from 20 rendered views. The fitted model's K6 at all 18 default poses against "
        f"the true K6 (relative Frobenius, rad as L mm; target 2 %): median {np.median(k6):.3f} %, worst "
        f"{k6.max():.3f} %; springs worst {100 * np.abs(E / T - 1).max():.3f} % (target 1 %); pooled RMS of "
        f"(estimate - truth) / reported std {np.sqrt(np.mean(((E - T) / S) ** 2)):.2f}."
        + (f" Mean time per campaign: simulate {np.mean(sim):.0f} s (machine shared)." if sim else "")
    )
    columns = ["spring", "truth N/mm", "max error %", "reported std %", "scatter %"]
    save("own_legs_3rps", "The shipped 3-RPS on the test-bed: its six springs and K6", columns, rows, intro)


def replace_select(args):
    """``args`` with the 3-RPS's selection as ``select`` (what :func:`campaign` reads)."""
    return argparse.Namespace(**{**vars(args), "select": args.rps3_select})


def intro(args, cases, results, forces, times) -> str:
    n = args.seeds
    per_case = "; ".join(
        f"**{c}** (largest force {np.linalg.norm(forces[c], axis=1).max():.4g} N): K6 median "
        f"{results[c]['k6_median']:.3f} %, worst {results[c]['k6_worst']:.3f} % (target 2 %), legs worst "
        f"{np.abs(results[c]['rel']).max():.3f} % (target 1 %), pooled RMS of (estimate - truth) / "
        f"reported std {results[c]['pooled']:.2f}, measured 3 x 3 K per position median "
        f"{results[c]['K_median']:.2f} %"
        for c in cases
    )
    sim = [t["simulate_s"] for t in times if t["simulate_s"] > 0]
    run = [t["run_s"] for t in times if t["run_s"] > 0]
    timing = (
        f"Mean time per campaign: simulate {np.mean(sim):.0f} s, run {np.mean(run):.0f} s ({args.workers} "
        "worker(s), machine shared)."
        if sim
        else "The campaigns were reused from --cache."
    )
    return (
        f"`stiffmap simulate OUT --robot my_hexapod.toml --seed S --select {args.select} --repeats "
        f"{args.repeats} [--loads paper9.csv]` then `stiffmap run OUT`, seeds 0..{n - 1}: the 6-UPS of "
        "`benchmarks/bench_own_legs.py` (base joints on a 220 mm circle, platform joints on a 120 mm "
        "circle, home 260 mm; legs 350-540 N/mm), positions of its default 3 x 3 x 2 grid (35 mm apart "
        "about its home, the platform level), loads hung 100 mm below the platform's centre, one camera "
        "calibrated from 20 rendered views. **scaled**: `--loads paper9` as `simulate` takes it for a "
        "robot of one's own (paper9 alone would move the tool point by 0.025 mm at most: its masses "
        "scaled x 50, 1.2 mm); **paper9**: the same forces unscaled, given as a CSV file; **paper9x10**: "
        "those forces x 10 in a CSV file. Legs fitted by "
        "`stiffmap run` (whitened by the displacements' full covariances plus an extra noise); errors, "
        "standard errors and scatter in % of the truth. The fitted model's K6 at each position against "
        f"the true K6 (relative Frobenius, rad as L mm). {per_case}. {timing}"
    )


if __name__ == "__main__":
    main()
