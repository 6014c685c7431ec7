"""Vendors' robot descriptions as published, through ``stiffmap model urdf``, against an independent
computation (issue 29).

The descriptions are public package trees (ROS-Industrial's ABB, Fanuc, KUKA, Motoman, Staubli and
Universal Robots support packages, Kinova, UFACTORY xArm, Kawasaki, Techman, Doosan, a Robotiq
gripper on an arm, example-robot-data's two-armed and mobile robots) rebuilt under a folder
(default /tmp/ros_real, its INDEX.md naming each file's repository and commit; meshes are never
opened, so they are left out). They are not shipped with stiffmap: not all of them are ours to
ship. Without the folder the benchmark says so and stops.

For each arm of :data:`ARMS` (file, tip, base, xacro arguments, package folders): the file is
expanded by the benchmark itself (the ``xacro`` package, ``$(find PKG)`` resolved by its own search
of the folder), read by ``tests/helpers/urdf_reference`` (its own XML reading, roll-pitch-yaw and
axis maths, forward kinematics, a mimic joint following its leader, the Jacobian by central
differences, C = J K^-1 J^T; no stiffmap code), and at 5 random configurations within the joint
limits (random joint stiffnesses) compared with what ``stiffmap model urdf FILE --json`` prints:
the measured point (tip frame + 10, -20, 30 mm), K and K6. A xacro file is also given to stiffmap
as the URDF the benchmark expanded: its K must be the xacro run's. Outcomes: ``agrees`` (every
relative difference below 1e-6), ``refused: <the line>`` when the reference agrees there is
nothing to compute, ``refused wrongly``, ``disagrees``, ``internal error``.

Then the bad cases of the issue on these trees (a floating joint on the chain, a tip on another
branch than the base, a mimic loop, an unresolved package or argument), each expected as one
``error:`` line naming the file and the element.

Run:  .venv/bin/python benchmarks/bench_vendor_urdf.py [--root /tmp/ros_real] [--configs 5]
Saves benchmarks/results/vendor_urdf.md.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import re
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import xacro
import xacro.substitution_args as xacro_subs

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from _table import save  # noqa: E402
from helpers import urdf_reference as ref  # noqa: E402

from stiffmap.cli.main import main as stiffmap  # noqa: E402

OFFSET = (10.0, -20.0, 30.0)  # mm, in the tip frame
TOL = 1e-6

# (label, file under the root, tip, base or None, xacro args, package folders under the root)
ARMS = [
    ("ABB IRB 120-3/0.58", "abb/abb_irb120_support/urdf/irb120_3_58.xacro", "tool0", None, {}, []),
    (
        "ABB IRB 4400 (parallelogram mimics off the chain)",
        "abb/abb_irb4400_support/urdf/irb4400.xacro",
        "tool0",
        None,
        {},
        [],
    ),
    (
        "ABB IRB 6640-185/2.80 (cylinder, piston mimics)",
        "abb/abb_irb6640_support/urdf/irb6640_185_280.xacro",
        "tool0",
        None,
        {},
        [],
    ),
    ("Fanuc LR Mate 200iD", "fanuc/fanuc_lrmate200id_support/urdf/lrmate200id.xacro", "tool0", None, {}, []),
    (
        "Fanuc LR Mate 200iD from its controller's frame (base, 0.33 m up)",
        "fanuc/fanuc_lrmate200id_support/urdf/lrmate200id.xacro",
        "tool0",
        "base",
        {},
        [],
    ),
    ("Fanuc M-430iA/2F (5 axes)", "fanuc/fanuc_m430ia_support/urdf/m430ia2f.xacro", "tool0", None, {}, []),
    ("Fanuc R-2000iC/165F", "fanuc/fanuc_r2000ic_support/urdf/r2000ic165f.xacro", "tool0", None, {}, []),
    ("KUKA KR 120 R2500 pro", "kuka/kuka_kr120_support/urdf/kr120r2500pro.xacro", "tool0", None, {}, []),
    (
        "Universal Robots UR5 (ROS 1, YAML, !degrees)",
        "universal_robot/ur_description/urdf/ur5.xacro",
        "tool0",
        None,
        {},
        [],
    ),
    (
        "Motoman SIA20D (7 axes, URDF)",
        "motoman/motoman_sia20d_support/urdf/sia20d.urdf",
        "tool0",
        None,
        {},
        [],
    ),
    (
        "Motoman CSDA10F left arm + torso (dual arm)",
        "motoman/motoman_csda10f_support/urdf/csda10f.xacro",
        "arm_left_link_tool0",
        None,
        {},
        [],
    ),
    (
        "Motoman CSDA10F right arm from the torso",
        "motoman/motoman_csda10f_support/urdf/csda10f.xacro",
        "arm_right_link_tool0",
        "torso_link_b1",
        {},
        [],
    ),
    ("Staubli TX2-60L", "staubli/staubli_tx2_60_support/urdf/tx2_60l.xacro", "tool0", None, {}, []),
    (
        "Kinova Jaco 2 j2n6s300 (3 fingers, ROS 1 tags)",
        "kinova-ros/kinova_description/urdf/j2n6s300_standalone.xacro",
        "j2n6s300_end_effector",
        None,
        {},
        [],
    ),
    ("UFACTORY xArm 6", "xarm_ros/xarm_description/urdf/xarm6_robot.urdf.xacro", "link_eef", None, {}, []),
    (
        "UFACTORY xArm 6 (robot macro, $(eval))",
        "xarm_ros/xarm_description/urdf/xarm6_robot_macro_top.urdf.xacro",
        "link_eef",
        None,
        {"limited": "true"},
        [],
    ),
    ("Kawasaki RS007N", "khi_robot/khi_rs_description/urdf/rs007n.urdf.xacro", "link6", None, {}, []),
    ("Techman TM5-900", "tmr_ros1/tm_description/xacro/tm5-900.urdf.xacro", "tool0", None, {}, []),
    (
        "Doosan M1013",
        "doosan-robot/dsr_description/xacro/m1013.urdf.xacro",
        "link6",
        None,
        {"namespace": "dsr"},
        [],
    ),
    (
        "Doosan M1013 + Robotiq 2F-85 (tip on a mimic finger)",
        "doosan-robot/dsr_description/xacro/m1013robotiq_2f.urdf.xacro",
        "robotiq_85_left_finger_tip_link",
        None,
        {"namespace": "dsr"},
        ["robotiq"],
    ),
]
ARMS += [
    (
        "Franka FR3 (franka_description: YAML limits read as attributes, ** block parameters)",
        "franka_ros/franka_description/robots/fr3/fr3.urdf.xacro",
        "fr3_link8",
        None,
        {},
        [],
    ),
    (
        "Denso (ROS 2: xacro.load_yaml, parent-scope defaults, a Gazebo $(find) of an absent package)",
        "denso_robot_ros/denso_robot_description/urdf/denso_robot.urdf.xacro",
        "tool0",
        None,
        {},
        [],
    ),
    (
        "Kinova Gen3 7-DOF (ROS 2 kortex)",
        "ros2_kortex/kortex_description/robots/gen3.xacro",
        "tool_frame",
        None,
        {"vision": "false"},
        [],
    ),
]
ARMS += [
    (f"example-robot-data {name}", f"example-robot-data/{path}", tip, base, {}, [])
    for name, path, tip, base in (
        (
            "Baxter right arm from the torso (two arms)",
            "baxter_description/urdf/baxter.urdf",
            "right_gripper",
            "torso",
        ),
        (
            "PR2 left arm from the torso",
            "pr2_description/urdf/pr2.urdf",
            "l_gripper_palm_link",
            "torso_lift_link",
        ),
        (
            "PR2 left arm and torso lift (prismatic)",
            "pr2_description/urdf/pr2.urdf",
            "l_gripper_palm_link",
            "base_link",
        ),
        (
            "TIAGo arm from the torso",
            "tiago_description/robots/tiago.urdf",
            "arm_tool_link",
            "torso_lift_link",
        ),
        ("Panda (mimic finger as tip)", "panda_description/urdf/panda.urdf", "panda_rightfinger", None),
    )
]


# ---------------------------------------------------------------- the reference's own xacro expansion


def _packages(root: Path) -> dict[str, Path]:
    """Every ROS package under ``root``: name (package.xml's, else the folder's) -> folder."""
    out: dict[str, Path] = {}
    for px in sorted(root.rglob("package.xml")):
        el = ET.parse(px).getroot().find("name")
        out.setdefault(el.text.strip() if el is not None and el.text else px.parent.name, px.parent)
    return out


_ROS1_TAGS = ("property", "macro", "include", "arg", "if", "unless", "insert_block")


def expand(path: Path, args: dict, root: Path) -> str:
    """The URDF a xacro file expands to, as ROS's xacro (ROS 1's unprefixed tags taken)."""
    pkgs = _packages(root)
    parse = xacro.parse

    def parse_ros1(inp, filename=None):
        doc = parse(inp, filename)
        for tag in _ROS1_TAGS:
            for el in list(doc.getElementsByTagName(tag)):
                el.tagName = el.nodeName = f"xacro:{tag}"
        return doc

    saved = xacro_subs._eval_find, xacro_subs._eval_dict.get("find")
    # a package only named in text (a Gazebo plugin's parameters) may be absent, as for stiffmap
    xacro_subs._eval_find = xacro_subs._eval_dict["find"] = lambda p: str(pkgs.get(p, f"/absent/{p}"))
    xacro.parse = parse_ros1
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            return xacro.process_file(str(path), mappings=dict(args)).toxml()
    finally:
        xacro.parse = parse
        xacro_subs._eval_find, xacro_subs._eval_dict["find"] = saved
        xacro.init_stacks(None)


# ---------------------------------------------------------------- one arm


def _limits(joints, coords) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = [], []
    for c in coords:
        j = joints[c]
        s, cap = (1000.0, 500.0) if j.type == "prismatic" else (1.0, 2 * math.pi)
        lo.append(max(j.lower * s, -cap))
        hi.append(min(j.upper * s, cap))
    return np.array(lo), np.array(hi)


def _reference(joints, chain, coords, q, k):
    return ref.stiffness(joints, chain, coords, q, k, OFFSET)[:3]


def _in_frame(joints, frame: str, p, K, K6):
    """Position, K and K6 of the root frame expressed in a frame fixed to the root (its joints
    from the root all fixed): p' = R^T (p - t), K' = R^T K R, K6' = D^T K6 D, D = diag(R, R)."""
    T = ref.transform(joints, ref.path(joints, frame), {})
    R, t = T[:3, :3], T[:3, 3] * 1000.0
    D = np.kron(np.eye(2), R)
    return (
        R.T @ (p - t),
        None if K is None else R.T @ K @ R,
        None if K6 is None else D.T @ K6 @ D,
    )


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def run(args: list[str]) -> tuple[int, str, str]:
    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        code = stiffmap([str(a) for a in args])
    return code, o.getvalue(), e.getvalue()


def check_arm(root: Path, arm, n_configs: int, rng, tmp: Path) -> dict:
    label, rel, tip, base, xargs, pkg_dirs = arm
    f = root / rel
    t0 = time.perf_counter()
    out = {
        "label": label,
        "file": rel,
        "tip": tip,
        "base": base or "(root)",
        "xargs": xargs,
        "n": 0,
        "tip_err": math.nan,
        "K_err": math.nan,
        "K6_err": math.nan,
        "expanded_err": math.nan,
    }
    if not f.is_file():
        out["outcome"] = "missing from the folder"
        return out
    text = expand(f, xargs, root) if f.suffix == ".xacro" else f.read_text()
    _, joints = ref.read_joints(text)
    beside = base is not None and base not in {joints[j].parent for j in ref.path(joints, tip)}
    chain = ref.path(joints, tip, None if beside else base)
    coords = ref.coordinates(joints, chain)
    out["n"] = len(coords)
    lo, hi = _limits(joints, coords)
    Q = rng.uniform(lo, hi, size=(n_configs, len(coords)))
    k = np.array(
        [rng.uniform(2e5, 2e6) if joints[c].type == "prismatic" else rng.uniform(2e7, 2e8) for c in coords]
    )
    cfg = tmp / f"{f.stem}_{len(coords)}_configs.csv"
    ref.write_configs(cfg, joints, coords, Q)
    common = [
        "--tip",
        tip,
        "--tip-offset-mm",
        ",".join(map(str, OFFSET)),
        "--configs",
        cfg,
        "--param",
        "k_theta=" + ",".join(f"{v:.17g}" for v in k),
        "--json",
    ]
    common += ["--base", base] if base else []
    extra = [a for n, v in xargs.items() for a in ("--xacro-arg", f"{n}={v}")]
    extra += [a for d in pkg_dirs for a in ("--package-path", root / d)]
    code, stdout, stderr = run(["model", "urdf", f, *common, *extra])
    refs = [_reference(joints, chain, coords, q, k) for q in Q]
    if beside:  # a fixed frame beside the chain (ROS-Industrial's base): everything in its axes
        refs = [_in_frame(joints, base, *r) for r in refs]
    out["outcome"] = _compare(code, stdout, stderr, refs, out)
    if f.suffix == ".xacro" and code in (0, 1):
        pre = tmp / f"{f.stem}.urdf"
        pre.write_text(text)
        c2, s2, _ = run(["model", "urdf", pre, *common])
        a, b = json.loads(stdout), json.loads(s2) if c2 in (0, 1) else []
        errs = [_rel(x["K"], y["K"]) for x, y in zip(a, b, strict=False) if x.get("K") and y.get("K")]
        out["expanded_err"] = max(errs) if len(errs) == len(a) and errs else math.inf
    out["seconds"] = time.perf_counter() - t0
    return out


def _compare(code, stdout, stderr, refs, out) -> str:
    if code == 3 or "internal error" in stderr:
        return "internal error: " + stderr.strip()[:200]
    if code == 2:
        if all(K is None for _, K, _ in refs):
            return "refused (the reference finds no K either): " + stderr.strip()[:160]
        return "refused wrongly: " + stderr.strip()[:200]
    recs = json.loads(stdout)
    errs = {"tip": [], "K": [], "K6": []}
    for rec, (p, K, K6) in zip(recs, refs, strict=True):
        errs["tip"].append(_rel(rec["position"], p))
        if "error" in rec:
            if K is not None:
                return f"disagrees: refuses a configuration the reference computes ({rec['error'][:120]})"
            continue
        if K is None:
            return "disagrees: stiffmap computes K where the reference finds none"
        errs["K"].append(_rel(rec["K"], K))
        if rec.get("K6") is not None and K6 is not None:
            errs["K6"].append(_rel(rec["K6"], K6))
        elif rec.get("K6") is None and K6 is not None and "note" in rec:
            out["k6_left_out"] = out.get("k6_left_out", 0) + 1  # near a joint singularity, as noted
        elif (rec.get("K6") is None) != (K6 is None):
            return "disagrees: K6 given by one side only"
    for key in errs:
        out[f"{key}_err"] = max(errs[key]) if errs[key] else math.nan
    worst = max(v for v in (out["tip_err"], out["K_err"], out["K6_err"]) if not math.isnan(v))
    left = (
        f" (K6 left out at {out['k6_left_out']} near-singular configuration(s), noted)"
        if "k6_left_out" in out
        else ""
    )
    return ("agrees" if worst < TOL else f"disagrees ({worst:.1e})") + left


# ---------------------------------------------------------------- the bad cases, on the real trees


def bad_cases(root: Path, tmp: Path) -> list[tuple[str, str]]:
    """(case, the error line stiffmap prints) for the issue's bad inputs, built from the real files."""
    cfg = tmp / "c7.csv"
    cfg.write_text("label," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\nc1,10,20,30,40,50,60,70\n")
    csda = root / "motoman/motoman_csda10f_support/urdf/csda10f.xacro"
    irb = root / "abb/abb_irb120_support/urdf/irb120_3_58.xacro"
    dsr = root / "doosan-robot/dsr_description/xacro/m1013robotiq_2f.urdf.xacro"
    cases = []
    if csda.is_file():
        cases.append(
            (
                "tip on another branch than --base",
                ["model", "urdf", csda, "--tip", "arm_right_link_tool0", "--base", "arm_left_link_1_s"],
            )
        )
        loop = tmp / "csda10f_mimic_loop.urdf"
        t = expand(csda, {}, root).replace(
            '<joint name="torso_joint_b1" type="revolute">',
            '<joint name="torso_joint_b1" type="revolute"><mimic joint="torso_joint_b2"/>',
        )
        loop.write_text(t)
        cases.append(
            ("mimic loop (torso b1 <-> b2)", ["model", "urdf", loop, "--tip", "arm_left_link_tool0"])
        )
    if irb.is_file():
        fl = tmp / "irb120_floating.urdf"
        fl.write_text(
            re.sub(r'(<joint name="joint_1" type=)"revolute"', r'\1"floating"', expand(irb, {}, root))
        )
        cases.append(("floating joint on the chain", ["model", "urdf", fl, "--tip", "tool0"]))
    if dsr.is_file():
        cases.append(
            (
                "unresolved package (robotiq_description)",
                ["model", "urdf", dsr, "--tip", "link6", "--xacro-arg", "namespace=dsr"],
            )
        )
        cases.append(
            (
                "unresolved argument (namespace)",
                ["model", "urdf", dsr, "--tip", "link6", "--package-path", root / "robotiq"],
            )
        )
    out = []
    for name, argv in cases:
        code, _, err = run([*argv, "--configs", cfg, "--param", "k_theta=1e8"])
        line = err.strip().replace(str(root) + "/", "").replace(str(tmp) + "/", "")
        ok = code == 2 and line.count("\n") == 0 and line.startswith("error:")
        out.append((name, ("" if ok else f"NOT ONE LINE (status {code}): ") + line))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", type=Path, default=Path("/tmp/ros_real"))
    ap.add_argument("--configs", type=int, default=5)
    ap.add_argument("--seed", type=int, default=29)
    a = ap.parse_args()
    if not a.root.is_dir():
        print(f"skipped: {a.root} does not exist (rebuild the description trees listed in its INDEX.md)")
        return
    rng = np.random.default_rng(a.seed)
    rows = []
    with tempfile.TemporaryDirectory() as td:
        for arm in ARMS:
            r = check_arm(a.root, arm, a.configs, rng, Path(td))
            fmt = lambda v: "-" if math.isnan(v) else f"{v:.1e}"  # noqa: E731
            xa = " ".join(f"{k}={v}" for k, v in r["xargs"].items()) or "-"
            rows.append(
                [
                    r["label"],
                    r["tip"],
                    r["base"],
                    xa,
                    r["n"],
                    r["outcome"],
                    fmt(r["tip_err"]),
                    fmt(r["K_err"]),
                    fmt(r["K6_err"]),
                    fmt(r["expanded_err"]),
                    f"{r.get('seconds', 0):.2f}",
                ]
            )
            print(" | ".join(map(str, rows[-1])), flush=True)
        bad = bad_cases(a.root, Path(td))
    agree = sum(r[5].startswith("agrees") for r in rows)
    notes = (
        f"{agree} of {len(rows)} arms agree with the independent computation ({a.configs} random "
        "configurations each within the joint limits, random joint stiffnesses; relative differences, "
        "1e-6 the bound). 'xacro = URDF' is the largest relative difference in K between the xacro "
        "file and the URDF the benchmark expanded from it.\n\nBad input on these trees, each one line:\n\n"
        + "\n".join(f"- {n}: `{line}`" for n, line in bad)
    )
    save(
        "vendor_urdf",
        "Vendors' robot descriptions through stiffmap model urdf (issue 29)",
        ["arm", "tip", "base", "xacro args", "joints", "outcome", "tip", "K", "K6", "xacro = URDF", "s"],
        rows,
        notes,
    )


if __name__ == "__main__":
    main()
