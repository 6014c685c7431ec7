"""``stiffmap compensate``: speed, the free tool spin, and the virtual test-bed end to end.

1. **Speed**: a generated CAM-style program of 10 000 lines (N-numbered; a serpentine pocket of
   straight passes joined by half-circle G3/G2 turns, ten depths, rapids between) compensated
   for the milling study's 3PRR (kj 525, kb 9 800 N/mm, rods E A 7e6 N) under a force turning
   with the feed (FT 300 N, FN 200 N) at 1 um: wall time of ``compensate_file`` (one process;
   the target: under 10 s on 2 cores). The Delta and the six-joint arm on shorter programs for
   reference.
2. **Free tool spin** on the six-joint arm holding a tool 120 mm off its flange's axis (an
   angled head; with the tool on the last joint's axis the spin only turns that joint): the
   worst deflection along the program with the spin fixed and chosen (``--free-tool-spin``).
3. **Test-bed end to end**: a campaign identifies the model from the test-bed's data -- the
   3PRR from its simulated LDV recordings (``stiffmap simulate --robot 3prr``, true kj 700 N/mm
   where the published model says 525), the arm from its simulated vision campaign
   (``stiffmap simulate --robot arm6``) -- ``stiffmap run`` fits it, and the program compensated
   with ``--from-campaign`` is "cut" by the simulated robot with its TRUE stiffness (the
   truth.json model): worst distance of the cut from the programmed path, uncompensated,
   compensated with the nominal model, compensated with the identified one (target: below 10 %
   of the uncompensated).

Run:  nice .venv/bin/python benchmarks/bench_compensate.py [--skip-arm-campaign]
Saves benchmarks/results/compensate.md.
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
from _table import markdown, write  # noqa: E402

from stiffmap.campaign.fitted import fitted_model  # noqa: E402
from stiffmap.campaign.truth import load_truth  # noqa: E402
from stiffmap.cli.main import main as stiffmap  # noqa: E402
from stiffmap.kinds import RobotDescription, build_robot  # noqa: E402
from stiffmap.machining import CompensateOptions, ForceSpec, compensate_file  # noqa: E402
from stiffmap.machining.field import field_for  # noqa: E402
from stiffmap.machining.forces import force_at  # noqa: E402
from stiffmap.machining.io import read_program  # noqa: E402
from stiffmap.machining.path import toolpath_from_moves  # noqa: E402
from stiffmap.models import arm6  # noqa: E402
from stiffmap.models.delta import DeltaRobot  # noqa: E402
from stiffmap.models.prr3 import PRR3  # noqa: E402
from stiffmap.models.serial import SerialRobot  # noqa: E402

STUDY = PRR3(area=100.0)  # E A = 7e6 N


def pocket_program(lines: int, width: float = 60.0, step: float = 2.0, r: float = 1.0) -> str:
    """A serpentine pocket: straight passes joined by half-circle turns, depth after depth."""
    out = ["%", "O2001 (GENERATED POCKET)", "N10 G90 G94 G17 G21 G40 G49 G80", "N20 G54"]
    n = 30
    z = 0.0
    while len(out) < lines - 3:
        z -= 0.5
        y = 0.0
        out += [f"N{n} G0 X0. Y0. Z5.", f"N{n + 10} G1 Z{z:.1f} F300."]
        n += 20
        going = True
        while len(out) < lines - 5 and y < 40.0:
            x_end = width if going else 0.0
            out.append(f"N{n} G1 X{x_end:.1f} Y{y:.1f} F1200.")
            n += 10
            y += step
            arc = "G3" if going else "G2"
            jv = step / 2
            out.append(f"N{n} {arc} X{x_end:.1f} Y{y:.1f} I0. J{jv:.1f}")
            n += 10
            going = not going
        out.append(f"N{n} G0 Z5.")
        n += 10
    out += [f"N{n} M30", "%"]
    return "\n".join(out[:lines]) + "\n"


def worst_cut_error(true_model, program: Path, out: Path, place, force: ForceSpec) -> tuple[float, float]:
    """Uncompensated and compensated worst distance of the cut from the programmed path, the program
    deflected by ``true_model`` (dense samples of the output's feed moves, 2 per mm)."""
    prog = toolpath_from_moves(read_program(program)[0].moves)
    done = toolpath_from_moves(read_program(out)[0].moves)
    fld = field_for(true_model, place)

    def samples(path):
        L = path.length()
        ms = [np.full(max(9, int(L[m] * 2) + 1), m) for m in np.flatnonzero(path.feed)]
        m = np.concatenate(ms)
        s = np.concatenate([np.linspace(0, 1, a.size) for a in ms])
        return m, s

    m, s = samples(prog)
    before = np.linalg.norm(fld(prog.point(m, s), force_at(prog, force, m, s)).delta, axis=1).max()
    m2, s2 = samples(done)
    C = done.point(m2, s2)
    F = np.broadcast_to(force.value, C.shape) if force.mode == "base" else None
    D = C + fld(C, F).delta
    feed = np.flatnonzero(prog.feed)
    dist = np.full(D.shape[0], np.inf)
    for k in feed:
        dist = np.minimum(dist, prog.distance(np.full(D.shape[0], k), D))
    return float(before), float(dist.max())


def speed(tmp: Path) -> list[list]:
    rows = []
    prog = tmp / "pocket10k.nc"
    prog.write_text(pocket_program(10_000))
    cases = [
        ("3PRR (milling study)", STUDY, prog, (360.0, 180.0, 0.0), ForceSpec.feed_frame((300.0, 200.0))),
        ("Delta", DeltaRobot(), prog, (-30.0, -20.0, -300.0), ForceSpec.feed_frame((4.0, 3.0, -2.0))),
    ]
    small = tmp / "pocket1k.nc"
    small.write_text(pocket_program(1_000))
    cases.append(
        (
            "six-joint arm",
            arm6.model(),
            small,
            (480.0, -30.0, 380.0),
            ForceSpec.feed_frame((20.0, 15.0, 10.0)),
        )
    )
    for name, model, p, place, force in cases:
        t0, c0 = time.perf_counter(), time.process_time()
        res = compensate_file(
            model,
            p,
            tmp / ("out_" + p.name),
            CompensateOptions(tolerance_um=1.0, place_mm=place, force=force),
        )
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        s = res.summary
        n_lines = len(p.read_text().splitlines())
        rows.append(
            [
                name,
                n_lines,
                s["feed_moves"],
                s["points_out"],
                f"{s['deflection_before_um']['worst']:.1f}",
                f"{s['residual_after_um']['worst']:.3f}",
                f"{dt:.2f}",
                f"{cpu:.2f}",
            ]
        )
        print(rows[-1], flush=True)
    return rows


def spin(tmp: Path) -> list[list]:
    robot = SerialRobot.from_urdf(
        arm6.URDF,
        arm6.TIP_FRAME,
        (120.0, 0.0, 80.0),
        k_theta=arm6.K_THETA,
        tool_rotation=arm6.TOOL_ROTATION,
        q_seed=np.radians(arm6.Q_SEED_DEG),
    )
    prog = HERE.parent / "tests" / "data" / "gcode" / "cncjs_toolpath.nc"
    rows = []
    for free in (False, True):
        t0 = time.perf_counter()
        res = compensate_file(
            robot,
            prog,
            tmp / f"spin_{free}.nc",
            CompensateOptions(
                tolerance_um=1.0,
                place_mm=(450.0, -40.0, 380.0),
                free_tool_spin=free,
                force=ForceSpec.feed_frame((100.0, 80.0, 50.0)),
            ),
        )
        s = res.summary
        rows.append(
            [
                "chosen per point" if free else "fixed (0)",
                f"{s['deflection_before_um']['worst']:.1f}",
                f"{s['deflection_before_um']['rms']:.1f}",
                f"{s['residual_after_um']['worst']:.3f}",
                f"{time.perf_counter() - t0:.1f}",
            ]
        )
        print(rows[-1], flush=True)
    return rows


def testbed(tmp: Path, arm: bool) -> list[list]:
    rows = []
    prog = HERE.parent / "tests" / "data" / "gcode" / "own_cam_mm.nc"
    runs = [
        (
            "3PRR, LDV recordings",
            ["--robot", "3prr", "--param", "kj=700"],
            (380.0, 200.0, 0.0),
            ForceSpec.constant((0.0, -490.5)),
        )
    ]
    if arm:
        runs.append(
            (
                "six-joint arm, vision",
                ["--robot", "arm6", "--select", "1,2,3,4,5,6,7,8,9,10,11,12"],
                (480.0, -30.0, 380.0),
                ForceSpec.constant((20.0, -15.0, 10.0)),
            )
        )
    for name, args, place, force in runs:
        camp = tmp / name.split(",")[0].replace(" ", "_")
        t0 = time.perf_counter()
        assert stiffmap(["simulate", str(camp), "--seed", "7", *args]) in (0, None)
        # exit 1: done, with notes (e.g. the fit's extra noise); the fit itself is checked below
        assert stiffmap(["run", str(camp), "-q", "--no-report"]) in (0, 1, None)
        truth = load_truth(camp / "truth.json")
        fitted = fitted_model(camp)
        true_model = _true_model(truth, fitted.mechanism)
        nominal = _nominal(fitted.mechanism)
        out_n, out_f = tmp / "nominal.nc", tmp / "fitted.nc"
        opts = CompensateOptions(tolerance_um=1.0, place_mm=place, force=force)
        compensate_file(nominal, prog, out_n, opts)
        proc_args = [
            "compensate",
            "--from-campaign",
            str(camp),
            "--path",
            str(prog),
            "--out",
            str(out_f),
            "--place",
            ",".join(map(str, place)),
            "--force-n",
            ",".join(map(str, force.value)),
            "--no-figures",
            "--json",
            "-q",
            "--tolerance-um",
            "1",
        ]
        assert stiffmap(proc_args) in (0, None)
        before, after_n = worst_cut_error(true_model, prog, out_n, place, force)
        _, after_f = worst_cut_error(true_model, prog, out_f, place, force)
        rows.append(
            [
                name,
                f"{1e3 * before:.1f}",
                f"{1e3 * after_n:.2f}",
                f"{1e3 * after_f:.3f}",
                f"{100 * after_f / before:.3f}",
                f"{time.perf_counter() - t0:.0f}",
            ]
        )
        print(rows[-1], flush=True)
    return rows


def _true_model(truth, fitted):
    """The test-bed's robot with its true stiffness (truth.json's robot parameters)."""
    robot = truth.data["robot"]
    params = {k: float(v) for k, v in robot["params"].items()}
    if isinstance(fitted, SerialRobot):
        return fitted.with_params(**{k: v for k, v in params.items() if k in fitted.param_names()})
    return build_robot(RobotDescription(robot["model"], params))


def _nominal(fitted):
    """The model before identification: the published 3PRR (kj 525), the arm's joints 20 % stiffer."""
    if isinstance(fitted, SerialRobot):
        return fitted.with_params(k_theta=[1.2 * k for k in arm6.K_THETA])
    return fitted.with_params(kj=525.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--skip-arm-campaign", action="store_true", help="Leave out the arm's vision campaign (minutes)."
    )
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        sp = speed(tmp)
        sn = spin(tmp)
        tb = testbed(tmp, not a.skip_arm_campaign)
    text = (
        "# stiffmap compensate: speed, free tool spin, test-bed end to end\n\n" + __doc__.split("\n\n", 1)[1]
    )
    text += "\n## Speed (tolerance 1 um, one process)\n\n" + markdown(
        [
            "model",
            "lines",
            "feed moves",
            "points written",
            "worst deflection (um)",
            "worst residual (um)",
            "wall time (s)",
            "CPU time (s)",
        ],
        sp,
    )
    text += (
        "\n\n## Free tool spin (six-joint arm, tool 120 mm off the flange axis, cncjs_toolpath.nc)\n\n"
        + markdown(
            ["spin", "worst deflection (um)", "RMS deflection (um)", "worst residual (um)", "time (s)"], sn
        )
    )
    text += "\n\n## Test-bed end to end (own_cam_mm.nc; the cut by the true robot)\n\n" + markdown(
        [
            "campaign",
            "uncompensated worst (um)",
            "nominal model worst (um)",
            "identified model worst (um)",
            "identified / uncompensated (%)",
            "time (s)",
        ],
        tb,
    )
    text += "\n\n" + json.dumps({"python": sys.version.split()[0]}) + "\n"
    write(HERE / "results" / "compensate.md", text)


if __name__ == "__main__":
    main()
