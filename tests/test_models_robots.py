"""Robot descriptions as published (issue 29): every URDF of a public collection loads, and what
``stiffmap model urdf --json`` prints equals an independent computation from the file's numbers.

The collection is ``example-robot-data`` (PyPI, a dev dependency): 69 URDFs of arms (UR3/5/10,
Panda, Kinova, xArm7, Z1, SO-100/101), two-armed and mobile robots (Baxter, PR2, TIAGo),
humanoids and quadrupeds, written by their makers and labs with all the clutter a published
description has (transmissions, gazebo tags, mimic joints, package:// meshes, many branches).
For each, the measured point is the link at the end of its longest chain of moving joints;
at random configurations within the joint limits, the tip position, K and K6 are checked
against ``helpers.urdf_reference`` (NumPy forward kinematics from the file's origins, axes and
mimic tags, the Jacobian by central differences, C = J K^-1 J^T) to 1e-6 relative.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import shutil
import sys
from importlib.metadata import distribution
from pathlib import Path

import numpy as np
import pytest
from helpers import urdf_reference as ref
from helpers.cli_process import run_in_process as _cli
from helpers.fuzz import FuzzCase, assert_handled, mutated_text, run_case
from helpers.poses import rpy_matrix
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.cli.main import run
from stiffmap.errors import InputError
from stiffmap.models.robot_files import expand_xacro
from stiffmap.models.serial import SerialRobot

OFFSET = (10.0, -20.0, 30.0)  # mm in the tip frame
TOL = 1e-6  # relative, the issue's


def _robots_dir() -> Path:
    return Path(
        str(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
    )


ROBOTS = sorted(_robots_dir().rglob("*.urdf"))


def _deepest_link(links, joints) -> tuple[str | None, int]:
    """The link with the most moving joints between it and its root (the first in file order)."""
    best, tip = 0, None
    for lk in links:
        n = sum(joints[j].type in ref.MOVING for j in ref.path(joints, lk))
        if n > best:
            best, tip = n, lk
    return tip, best


def _limits(joints, coords) -> tuple[np.ndarray, np.ndarray]:
    """Sampling ranges (rad, mm): the file's limits within +-pi (+-100 mm for a prismatic joint)."""
    lo, hi = [], []
    for c in coords:
        j = joints[c]
        s = 1000.0 if j.type == "prismatic" else 1.0
        inf = 100.0 if j.type == "prismatic" else math.pi
        lo.append(max(j.lower * s, -inf))
        hi.append(min(j.upper * s, inf))
    return np.array(lo), np.array(hi)


def _reference(joints, chain, coords, q, k):
    """Tip position, K, K6 (None where singular) and the translation rank measure, independently."""
    return ref.stiffness(joints, chain, coords, q, k, OFFSET)


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """Every URDF of the collection through ``stiffmap model urdf --json``: (name, outcome) pairs."""
    mp = pytest.MonkeyPatch()
    out = []
    rng = np.random.default_rng(29)
    tmp = tmp_path_factory.mktemp("robots")
    try:
        for f in ROBOTS:
            out.append((str(f.relative_to(_robots_dir())), _one(f, rng, tmp, mp)))
    finally:
        mp.undo()
    return out


def _one(f: Path, rng, tmp: Path, mp) -> dict:
    text = f.read_text()
    links, joints = ref.read_joints(text)
    tip, _ = _deepest_link(links, joints)
    res: dict = {"tip": tip}
    if tip is None:
        res["expect_refusal"] = "no moving joint in the file"
    try:
        chain = ref.path(joints, tip) if tip else []
        coords = ref.coordinates(joints, chain) if tip else []
    except KeyError as e:  # a mimic naming a joint the file does not define
        res["expect_refusal"] = f"mimic of missing joint {e}"
        coords = []
    Q = []
    if coords:
        lo, hi = _limits(joints, coords)
        Q = rng.uniform(lo, hi, size=(3, len(coords)))
    k = np.array(
        [rng.uniform(2e5, 2e6) if joints[c].type == "prismatic" else rng.uniform(2e7, 2e8) for c in coords]
    )
    cfg = tmp / f"{f.stem}_configs.csv"
    if coords:
        ref.write_configs(cfg, joints, coords, Q)
    else:
        cfg.write_text("q1_deg\n0\n")
    args = ["model", "urdf", f, "--tip", tip or "base_link", "--tip-offset-mm", ",".join(map(str, OFFSET))]
    args += ["--configs", cfg, "--param", "k_theta=" + (",".join(f"{v:.17g}" for v in k) or "1e8"), "--json"]
    code, out, err = _run(args, mp)
    res.update(
        code=code, out=out, err=err, joints=joints, chain=chain if tip else [], coords=coords, Q=Q, k=k
    )
    return res


def _run(args, mp):
    """``stiffmap ARGS`` in this process (the module fixture has no capsys): (status, stdout, stderr)."""
    o, e = io.StringIO(), io.StringIO()
    mp.setattr(sys, "argv", ["stiffmap", *map(str, args)])
    code = 0
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        try:
            run()
        except SystemExit as ex:
            code = ex.code or 0
    return code, o.getvalue(), e.getvalue()


def _no_k_anywhere(r) -> bool:
    """The reference finds no K at any of the robot's configurations (a planar two-joint chain)."""
    return bool(r["coords"]) and all(
        _reference(r["joints"], r["chain"], r["coords"], q, r["k"])[1] is None for q in r["Q"]
    )


def test_every_published_description_loads_or_is_refused_for_a_real_reason(sweep):
    for _, r in sweep:
        if r["code"] == 2 and "expect_refusal" not in r and _no_k_anywhere(r):
            r["expect_refusal"] = "the joints cannot move the point in every direction"
            assert "singular: the joints cannot move the point along" in r["err"], r["err"]
    refused = {name: r["err"].strip() for name, r in sweep if r["code"] == 2 and "expect_refusal" in r}
    unexpected = [
        (name, r["err"].strip()) for name, r in sweep if r["code"] == 2 and "expect_refusal" not in r
    ]
    assert not unexpected, "\n".join(f"{a}: {b}" for a, b in unexpected)
    missed = [name for name, r in sweep if "expect_refusal" in r and r["code"] != 2]
    assert not missed, missed
    # The refusals, each one line naming the file and why (listed in docs/models.md).
    for name, line in refused.items():
        f = Path(name)
        assert line.startswith("error: ") and line.count("\n") == 0, line
        assert f.name in line or f"{f.stem}_configs.csv" in line, line
    assert len(sweep) == len(ROBOTS) >= 60
    assert len(refused) <= 12, refused


def test_tip_position_k_and_k6_equal_an_independent_computation(sweep):
    checked_k = checked_k6 = 0
    for name, r in sweep:
        if r["code"] == 2:
            continue
        recs = json.loads(r["out"])
        assert len(recs) == len(r["Q"]), name
        for rec, q in zip(recs, r["Q"], strict=True):
            types = [r["joints"][c].type for c in r["coords"]]
            q_file = [
                v if t == "prismatic" else math.radians(v) for t, v in zip(types, rec["q_deg"], strict=True)
            ]
            np.testing.assert_allclose(q_file, q, rtol=1e-9, atol=1e-9)
            p, K, K6, trans = _reference(r["joints"], r["chain"], r["coords"], q, r["k"])
            if "error" in rec:
                # Refused only where the joints (almost) cannot move the point in every direction:
                # the reference finds no K there either (a joint singularity alone gives K, a note).
                assert "singular" in rec["error"] and K is None, (name, rec["error"])
                continue
            assert _rel(rec["position"], p) < TOL or np.linalg.norm(np.subtract(rec["position"], p)) < 1e-9
            assert K is not None, (name, trans)
            e = _rel(rec["K"], K)
            assert e < TOL, (name, e)
            checked_k += 1
            if rec["K6"] is not None:
                assert K6 is not None, name
                e6 = _rel(rec["K6"], K6)
                assert e6 < TOL, (name, e6)
                checked_k6 += 1
    assert checked_k >= 100 and checked_k6 >= 60, (checked_k, checked_k6)


CLUTTERED = Path(__file__).parent / "robots" / "cluttered_mm.urdf"


def test_the_arm_inside_a_mobile_manipulator_with_a_mimic_finger(rng):
    """base_link as the base frame (the planar joint above it held), the tip on the finger that
    mimics the other (its leader off the path, a coordinate), a spring of the mimic joint's own:
    position, Jacobian and K6 against the independent computation."""
    links, joints = ref.read_joints(CLUTTERED.read_text())
    chain = ref.path(joints, "r_finger_right", "base_link")
    coords = ref.coordinates(joints, chain)
    k = np.array([5e5, 4e8, 4e8, 2e8, 5e7, 5e7, 3e7, 2e5, 1e5])  # N/mm (lift, fingers), N*mm/rad
    robot = SerialRobot.from_urdf(CLUTTERED, "r_finger_right", OFFSET, base_frame="base_link", k_theta=k)
    ch = robot.chain
    assert ch.joint_names == (
        "torso_lift_joint",
        *(f"r_joint_{i}" for i in range(1, 7)),
        "r_finger_left_joint",
    )
    assert list(ch.joint_names) == coords and ch.mimic_names == ("r_finger_right_joint",)
    assert robot.param_names() == tuple(f"k{i}" for i in range(1, 10))
    lo, hi = _limits(joints, coords)
    for q in rng.uniform(lo, hi, size=(4, len(coords))):
        p, _ = ref.tip_pose_mm(joints, chain, coords, q, OFFSET)
        J = ref.jacobian_fd(joints, chain, coords, q, OFFSET)
        Jm = ref.joint_column_fd(joints, chain, coords, q, OFFSET, "r_finger_right_joint")
        C = J @ np.diag(1 / k[:-1]) @ J.T + np.outer(Jm, Jm) / k[-1]
        assert _rel(ch.forward(q)[0], p) < 1e-12
        assert _rel(ch.jacobian(q), J) < 1e-8
        assert _rel(robot.stiffness6(q), np.linalg.inv(C)) < TOL
        assert _rel(robot.stiffness3(q), np.linalg.inv(C[:3, :3])) < TOL
    # The mimic finger's coordinate: minus its leader's, within its own limits [-40, 0] mm.
    q = np.zeros(len(coords))
    q[-1] = 30.0
    np.testing.assert_allclose(ch.mimic_coordinates(q), [-30.0])
    q[-1] = -10.0  # the leader below its limit, the follower above its own
    assert ch.beyond_limits(q) == [
        "joint r_finger_left_joint at -10 mm beyond its limits [0, 40] mm",
        "joint r_finger_right_joint at 10 mm beyond its limits [-40, 0] mm",
    ]


@pytest.mark.parametrize(
    "tip, base, edit, message",
    [
        (
            "r_tool0",
            None,
            None,
            "joint 'base_planar' (on the chain from 'odom' to 'r_tool0') is planar (3 degrees of freedom, no "
            "spring a stiffness model can give): choose a base frame below it (--base base_link",
        ),
        (
            "caster",
            "base_link",
            None,
            "joint 'caster_joint' (on the chain from 'base_link' to 'caster') is floating",
        ),
        (
            "r_tool0",
            "l_arm_base",
            None,
            "tip frame 'r_tool0' is not below base frame 'l_arm_base': the chain from the root 'odom' to "
            "'r_tool0' passes through links odom, base_link, torso, r_arm_base",
        ),
        ("r_tool0", "l_arm", None, "no frame 'l_arm' for the base frame; the links are: odom, base_link"),
        (
            "r_finger_right",
            "base_link",
            ('<mimic joint="r_finger_left_joint"', '<mimic joint="r_finger_middle_joint"'),
            "joint 'r_finger_right_joint': <mimic joint='r_finger_middle_joint'> names a joint the file "
            "does not define",
        ),
        (
            "r_finger_right",
            "base_link",
            (
                '<limit lower="0" upper="0.04"',
                '<mimic joint="r_finger_right_joint"/><limit lower="0" upper="0.04"',
            ),
            "joint 'r_finger_right_joint': mimic loop r_finger_right_joint -> r_finger_left_joint -> "
            "r_finger_right_joint: no joint leads",
        ),
        (
            "r_tool0",
            "base_link",
            (
                '<origin xyz="0 0 0.3"/><axis xyz="0 1 0"/><limit lower="-2.5"',
                '<origin xyz="1e300 0 0.3"/><axis xyz="0 1 0"/><limit lower="-2.5"',
            ),
            "joint 'r_joint_3' (on the chain from 'base_link' to 'r_tool0'): <origin xyz> 1e+300 0 0.3 m "
            "is beyond",
        ),
    ],
)
def test_descriptions_that_cannot_be_modelled_are_named(tmp_path, tip, base, edit, message):
    f = CLUTTERED
    if edit is not None:
        text = CLUTTERED.read_text()
        assert edit[0] in text
        f = tmp_path / "edited.urdf"
        f.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(f, tip, base_frame=base, k_theta=1e8)
    assert str(e.value).startswith(f"{f}: ") and message in str(e.value), str(e.value)
    assert "\n" not in str(e.value)


XACRO_WS = Path(__file__).parent / "robots" / "xacro_ws"
ACME_XACRO = XACRO_WS / "acme_description" / "urdf" / "acme_rs6.urdf.xacro"
ACME_URDF = Path(__file__).parent / "robots" / "acme_rs6.urdf"
K_ACME = (4e8, 4e8, 2e8, 5e7, 5e7, 3e7)


def test_a_xacro_description_gives_the_k_of_its_pre_expanded_urdf(rng, monkeypatch):
    """Split over two packages (the shared one found by its package.xml's name, not its folder's),
    with macros, properties, math, a conditional, includes through $(find PKG) and an argument
    without default: the same K6 and K, to round-off, as the URDF written out by hand."""
    xa = SerialRobot.from_urdf(
        ACME_XACRO,
        "tool0",
        OFFSET,
        k_theta=K_ACME,
        xacro_args={"mount_height": "0.4"},
        package_paths=[XACRO_WS],
    )
    plain = SerialRobot.from_urdf(ACME_URDF, "tool0", OFFSET, k_theta=K_ACME)
    assert xa.chain.joint_names == plain.chain.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    np.testing.assert_allclose(xa.chain.lower, plain.chain.lower, rtol=1e-15)
    Q = rng.uniform(plain.chain.lower, plain.chain.upper, size=(5, 6))
    assert _rel(xa.stiffness6(Q), plain.stiffness6(Q)) < 1e-12
    assert _rel(xa.compliance6(Q), plain.compliance6(Q)) < 1e-12
    # ROS_PACKAGE_PATH serves as well as --package-path.
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"/nonexistent{os.pathsep}{XACRO_WS}")
    env = SerialRobot.from_urdf(
        ACME_XACRO, "tool0", OFFSET, k_theta=K_ACME, xacro_args={"mount_height": "0.4"}
    )
    assert _rel(env.chain.forward(Q[0])[0], plain.chain.forward(Q[0])[0]) < 1e-15


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (
            {"package_paths": [XACRO_WS]},
            "xacro: argument 'mount_height' has no value: give it with --xacro-arg mount_height=VALUE",
        ),
        (
            {"xacro_args": {"mount_height": "zero"}, "package_paths": [XACRO_WS]},
            "joint 'world-base_link' (on the chain from 'world' to 'tool0'): <origin xyz> is not three",
        ),
    ],
)
def test_xacro_that_cannot_be_expanded_is_one_line(monkeypatch, kwargs, message):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(ACME_XACRO, "tool0", k_theta=1e8, **kwargs)
    assert str(e.value).startswith(f"{ACME_XACRO}: ") and message in str(e.value), str(e.value)
    assert "\n" not in str(e.value)


def test_the_files_own_workspace_is_searched_last(rng, monkeypatch, tmp_path):
    """No --package-path, no ROS_PACKAGE_PATH: $(find PKG) finds the file's own package and its
    siblings (the folder holding its package, as a workspace's source folder does); a copy
    outside any package finds nothing and says so, naming the package."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    args = {"mount_height": "0.4"}
    ws = SerialRobot.from_urdf(ACME_XACRO, "tool0", OFFSET, k_theta=K_ACME, xacro_args=args)
    given = SerialRobot.from_urdf(
        ACME_XACRO, "tool0", OFFSET, k_theta=K_ACME, xacro_args=args, package_paths=[XACRO_WS]
    )
    Q = rng.uniform(given.chain.lower, given.chain.upper, size=(3, 6))
    assert _rel(ws.stiffness6(Q), given.stiffness6(Q)) < 1e-15
    alone = tmp_path / ACME_XACRO.name
    shutil.copy(ACME_XACRO, alone)
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(alone, "tool0", k_theta=1e8, xacro_args=args)
    assert str(e.value) == (
        f"{alone}: xacro: $(find acme_description): no package 'acme_description' in the package "
        "folders (none given); give its folder with --package-path DIR (campaign.toml: "
        "package_paths) or ROS_PACKAGE_PATH"
    )
    # The package without its sibling: the workspace searched is named.
    pkg = shutil.copytree(XACRO_WS / "acme_description", tmp_path / "ws" / "acme_description")
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(pkg / "urdf" / ACME_XACRO.name, "tool0", k_theta=1e8, xacro_args=args)
    assert (
        f"xacro: $(find acme_resources): no package 'acme_resources' in the package folders "
        f"({tmp_path / 'ws'});" in str(e.value)
    ), str(e.value)


def test_xacro_errors_of_its_own_are_one_line(tmp_path):
    broken = tmp_path / "broken.urdf.xacro"
    broken.write_text(
        '<robot name="b" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="missing_macros.xacro"/></robot>'
    )
    with pytest.raises(InputError, match=r"broken\.urdf\.xacro: xacro: .*missing_macros\.xacro") as e:
        SerialRobot.from_urdf(broken, "tool0", k_theta=1e8)
    assert "\n" not in str(e.value)
    with pytest.raises(
        InputError, match=r"acme_rs6\.urdf: xacro arguments \(mount_height\) given, but the file"
    ):
        SerialRobot.from_urdf(ACME_URDF, "tool0", k_theta=1e8, xacro_args={"mount_height": "0.4"})


ONE_JOINT = """<robot name="turntable"><link name="base"/><link name="plate"/>
  <joint name="turn" type="continuous"><parent link="base"/><child link="plate"/><axis xyz="0 0 1"/></joint>
</robot>"""


def test_a_one_joint_description_and_absurd_numbers_are_answered(tmp_path, monkeypatch, capsys):
    """Issue 27: a one-joint URDF (Pinocchio's Jacobian is then a vector) gives its Jacobian; a tip
    offset of 1e300 mm is refused by name rather than failing deep in an SVD."""
    f = tmp_path / "turntable.urdf"
    f.write_text(ONE_JOINT)
    robot = SerialRobot.from_urdf(f, "plate", (100.0, 0.0, 0.0), k_theta=1e6)
    np.testing.assert_allclose(
        robot.chain.jacobian([0.3]),
        [[-100 * math.sin(0.3)], [100 * math.cos(0.3)], [0], [0], [0], [1]],
        atol=1e-12,
    )
    cfg = tmp_path / "c.csv"
    cfg.write_text("turn_deg\n30\n")
    code, out, err = _cli(
        [
            "model",
            "urdf",
            f,
            "--tip",
            "plate",
            "--tip-offset-mm",
            "100,0,0",
            "--configs",
            cfg,
            "--param",
            "k_theta=1e6",
            "--json",
        ],
        monkeypatch,
        capsys,
    )
    assert code == 2 and "singular: the joints cannot move the point along" in err and err.count("\n") == 1
    code, out, err = _cli(
        [
            "model",
            "urdf",
            f,
            "--tip",
            "plate",
            "--tip-offset-mm",
            "1e300,0,0",
            "--configs",
            cfg,
            "--param",
            "k_theta=1e6",
        ],
        monkeypatch,
        capsys,
    )
    assert code == 2 and err.startswith(
        f"error: {f}: tip offset must be three finite numbers within 1e+06 mm"
    )


_CFG = b"q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,20,-30,40,50,60\n"


@pytest.mark.fuzz
@given(raw=st.one_of(mutated_text(ACME_URDF.read_text()), mutated_text(CLUTTERED.read_text())))
def test_mutated_descriptions_load_or_are_refused_by_name(raw):
    """`stiffmap model urdf` on a mutated URDF: an answer, or one line naming the file."""
    case = FuzzCase(
        files={"robot.urdf": raw, "configs.csv": _CFG},
        argv=(
            "model",
            "urdf",
            "{dir}/robot.urdf",
            "--tip",
            "tool0",
            "--configs",
            "{dir}/configs.csv",
            "--param",
            "k_theta=1e8",
            "--json",
        ),
        blamed="robot.urdf",
    )
    o = run_case(case)
    if o.code in (1, 2) and o.stderr.startswith("error: ") and "configs.csv" in o.stderr:
        return  # a mutation that changed the joints or made the configuration singular: said so
    assert_handled(case, o)


def test_a_description_in_a_default_namespace_reads_as_without(tmp_path):
    text = ACME_URDF.read_text().replace(
        '<robot name="acme_rs6">', '<robot xmlns="http://www.ros.org" name="acme_rs6">'
    )
    f = tmp_path / "ns.urdf"
    f.write_text(text)
    ns = SerialRobot.from_urdf(f, "tool0", OFFSET, k_theta=K_ACME)
    plain = SerialRobot.from_urdf(ACME_URDF, "tool0", OFFSET, k_theta=K_ACME)
    q = np.radians([10.0, 20.0, -30.0, 40.0, 50.0, 60.0])
    assert _rel(ns.stiffness6(q), plain.stiffness6(q)) < 1e-15


def test_a_fixed_frame_beside_the_chain_is_a_base_frame(rng, tmp_path):
    """ROS-Industrial's ``base`` (a fixed frame hung off ``base_link``, nothing below it): the
    tip's position, K and K6 in it are those in base_link moved by the constant transform,
    computed here from the numbers written in the file; a frame with a moving joint below it
    is the base of another branch and is named."""
    xyz, rpy = np.array([20.0, -30.0, 450.0]), (0.1, -0.2, 3.1)
    mount = (
        '<link name="base"/><link name="marker"/>'
        '<joint name="base_link-base" type="fixed"><parent link="base_link"/><child link="base"/>'
        f'<origin xyz="{xyz[0] / 1e3} {xyz[1] / 1e3} {xyz[2] / 1e3}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
        '</joint><joint name="base-marker" type="fixed"><parent link="base"/><child link="marker"/>'
        '<origin xyz="0 0 0.01"/></joint></robot>'
    )
    f = tmp_path / "acme_base.urdf"
    f.write_text(ACME_URDF.read_text().replace("</robot>", mount))
    plain = SerialRobot.from_urdf(f, "tool0", OFFSET, k_theta=K_ACME, base_frame="base_link")
    based = SerialRobot.from_urdf(f, "tool0", OFFSET, k_theta=K_ACME, base_frame="base")
    assert based.chain.joint_names == plain.chain.joint_names
    R = rpy_matrix(*rpy)
    T = np.zeros((6, 6))
    T[:3, :3] = T[3:, 3:] = R
    for q in rng.uniform(plain.chain.lower, plain.chain.upper, size=(4, 6)):
        p = plain.chain.forward(q)[0]
        assert np.max(np.abs(based.chain.forward(q)[0] - R.T @ (p - xyz))) < 1e-9
        assert _rel(based.stiffness6(q), T.T @ plain.stiffness6(q) @ T) < 1e-12
    moving = tmp_path / "acme_base_moving.urdf"
    moving.write_text(
        f.read_text().replace(
            '<joint name="base-marker" type="fixed">',
            '<joint name="base-marker" type="revolute"><axis xyz="0 0 1"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/>',
        )
    )
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(moving, "tool0", k_theta=K_ACME, base_frame="base")
    assert "'base' is on another branch: joint 'base-marker' moves below it (the base of another " in str(
        e.value
    )


def _ros1_style(tmp_path) -> Path:
    """The xacro workspace copied with ROS 1's unprefixed tags (<property>, <macro>, <include>,
    <arg>), as older ROS-Industrial descriptions write them."""
    ws = shutil.copytree(XACRO_WS, tmp_path / "ros1_ws")
    for f in ws.rglob("*.xacro"):
        text = f.read_text()
        for tag in ("property", "macro", "include", "arg"):
            text = text.replace(f"<xacro:{tag} ", f"<{tag} ").replace(f"</xacro:{tag}>", f"</{tag}>")
        f.write_text(text)
    return ws / "acme_description" / "urdf" / ACME_XACRO.name


def test_ros1_unprefixed_xacro_tags_expand_as_ros1_did(rng, tmp_path):
    """ROS 1's xacro took <property>, <macro>, <include> without the prefix (xacro 2 ignores
    them): the same K6 as the prefixed description; an error inside a macro names it."""
    old = _ros1_style(tmp_path)
    assert "<xacro:property" not in (old.parent / "acme_rs6_macro.xacro").read_text()
    args = {"mount_height": "0.4"}
    a = SerialRobot.from_urdf(old, "tool0", OFFSET, k_theta=K_ACME, xacro_args=args)
    b = SerialRobot.from_urdf(
        ACME_XACRO, "tool0", OFFSET, k_theta=K_ACME, xacro_args=args, package_paths=[XACRO_WS]
    )
    Q = rng.uniform(b.chain.lower, b.chain.upper, size=(3, 6))
    assert _rel(a.stiffness6(Q), b.stiffness6(Q)) < 1e-15
    macro = old.parent / "acme_rs6_macro.xacro"
    macro.write_text(macro.read_text().replace('xyz="0 0 ${d1}"', 'xyz="0 0 ${d_one}"', 1))
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(old, "tool0", k_theta=1e8, xacro_args=args)
    msg = str(e.value)
    assert "name 'd_one' is not defined" in msg and f"(in macro 'acme_joint' of {macro.resolve()})" in msg, (
        msg
    )
    assert "\n" not in msg


def _package_uri_style(tmp_path) -> Path:
    """The xacro workspace with its includes written ``package://PKG/...`` (ROS 2 descriptions'
    style) instead of ``$(find PKG)/...``."""
    ws = shutil.copytree(XACRO_WS, tmp_path / "uri_ws")
    for f in ws.rglob("*.xacro"):
        text = f.read_text()
        f.write_text(re.sub(r'filename="\$\(find ([\w-]+)\)/', r'filename="package://\1/', text))
    return ws / "acme_description" / "urdf" / ACME_XACRO.name


def test_includes_by_package_uri_expand_as_find(rng, tmp_path):
    """<xacro:include filename="package://PKG/urdf/x.xacro"> (the PyPI xacro takes it for a
    relative path) is found as $(find PKG) is, a package found by its package.xml's name too:
    the same K6 as the description written out by hand; a package no folder holds is named."""
    top = _package_uri_style(tmp_path)
    assert "package://acme_resources/" in (top.parent / "acme_rs6_macro.xacro").read_text()
    args = {"mount_height": "0.4"}
    a = SerialRobot.from_urdf(top, "tool0", OFFSET, k_theta=K_ACME, xacro_args=args)
    plain = SerialRobot.from_urdf(ACME_URDF, "tool0", OFFSET, k_theta=K_ACME)
    Q = rng.uniform(plain.chain.lower, plain.chain.upper, size=(3, 6))
    assert _rel(a.stiffness6(Q), plain.stiffness6(Q)) < 1e-12
    shutil.rmtree(top.parents[2] / "common")  # the package acme_resources
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(top, "tool0", k_theta=1e8, xacro_args=args)
    assert "xacro: $(find acme_resources): no package 'acme_resources' in the package folders" in str(e.value)


def test_xacro_messages_that_name_the_description_s_own_faults(tmp_path):
    """An argument a macro call needs is global: named without a macro's place; a property
    named with '__' (refused by xacro since 2021, common in older descriptions) says why."""
    f = tmp_path / "cell.urdf.xacro"
    f.write_text(
        '<robot name="c" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:macro name="arm" params="namespace"><link name="${namespace}base"/></xacro:macro>'
        '<xacro:arm namespace="$(arg namespace)"/></robot>'
    )
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(f, "base", k_theta=1e8)
    assert str(e.value) == (
        f"{f}: xacro: argument 'namespace' has no value: give it with --xacro-arg namespace=VALUE "
        "(campaign.toml: xacro_args)"
    )
    f.write_text(
        '<robot name="c" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="__limits" value="1"/><link name="base"/></robot>'
    )
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(f, "base", k_theta=1e8)
    assert "double underscore:__limits (xacro refuses property names starting with '__' since 2021" in str(
        e.value
    )
    assert "\n" not in str(e.value)


def test_a_package_named_only_in_text_need_not_be_found(tmp_path):
    """$(find PKG) in a Gazebo plugin's parameters (Denso's ROS 2 description, sim_gazebo true by
    default) names a package the kinematic tree does not need: the description loads as without
    it; the same package needed to load a file is named, in one line."""
    f = tmp_path / "cell.urdf.xacro"
    gazebo = (
        "<gazebo><plugin filename='gz_ros2_control-system' name='p'>"
        "<parameters>$(find acme_bringup)/config/controllers.yaml</parameters></plugin></gazebo>"
    )
    f.write_text(
        f'<robot name="c" xmlns:xacro="http://www.ros.org/wiki/xacro">{ONE_JOINT[24:-8]}{gazebo}</robot>'
    )
    robot = SerialRobot.from_urdf(f, "plate", k_theta=1e8)
    assert robot.chain.joint_names == ("turn",)
    # The expansion (copied into a simulated campaign) keeps the $(find) as written.
    assert "<parameters>$(find acme_bringup)/config/controllers.yaml</parameters>" in expand_xacro(f)
    f.write_text(
        '<robot name="c" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        "<xacro:property name='q0' lazy_eval='false' "
        "value=\"${xacro.load_yaml('$(find acme_bringup)/config/q0.yaml')}\"/>"
        f"{ONE_JOINT[24:-8]}</robot>"
    )
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(f, "plate", k_theta=1e8)
    assert str(e.value).startswith(
        f"{f}: xacro: $(find acme_bringup): no package 'acme_bringup' in the package"
    )
    assert "\n" not in str(e.value)


def test_a_missing_file_named_by_an_argument_s_default_names_the_argument(tmp_path):
    """Universal Robots' ROS 2 description: <robot name="$(arg name)"> (xacro reads the root's
    attributes before its xacro:arg elements, so name must be given) and ur_type defaulting to
    the non-existent 'ur5x', whose YAML files xacro.load_yaml then cannot open: the line says
    which argument to give."""
    cfg = tmp_path / "config" / "ur5e"
    cfg.mkdir(parents=True)
    (cfg / "joint_limits.yaml").write_text("joint_limits: {lift: 1.0}\n")
    f = tmp_path / "ur.urdf.xacro"
    f.write_text(
        '<robot name="$(arg name)" xmlns:xacro="http://wiki.ros.org/xacro">'
        '<xacro:arg name="name" default="ur"/><xacro:arg name="ur_type" default="ur5x"/>'
        f"<xacro:property name='limits' lazy_eval='false' "
        f"value=\"${{xacro.load_yaml('{tmp_path}/config/$(arg ur_type)/joint_limits.yaml')}}\"/>"
        f"{ONE_JOINT[24:-8]}</robot>"
    )
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(f, "plate", k_theta=1e8)
    assert "xacro: argument 'name' has no value: give it with --xacro-arg name=VALUE" in str(e.value)
    with pytest.raises(InputError) as e:
        SerialRobot.from_urdf(f, "plate", k_theta=1e8, xacro_args={"name": "ur"})
    assert "ur5x/joint_limits.yaml" in str(e.value) and str(e.value).endswith(
        "(argument 'ur_type' is 'ur5x' there by default: give it with --xacro-arg ur_type=VALUE, "
        "campaign.toml: xacro_args)"
    ), str(e.value)
    robot = SerialRobot.from_urdf(f, "plate", k_theta=1e8, xacro_args={"name": "ur", "ur_type": "ur5e"})
    assert robot.chain.joint_names == ("turn",)


def test_xacro_saved_as_urdf_is_expanded_and_a_written_out_urdf_is_not(rng, tmp_path):
    """A .urdf that declares the xacro namespace and uses it (macros, $(find), $(arg)) is xacro
    under a URDF's name: expanded, the K6 of the URDF written by hand; a URDF xacro wrote out
    (Motoman's sia20d.urdf: the namespace kept, nothing of xacro in it) is read as it is, and
    xacro arguments given to it are refused."""
    ws = shutil.copytree(XACRO_WS, tmp_path / "ws")
    top = ws / "acme_description" / "urdf" / "acme_rs6.urdf.xacro"
    as_urdf = top.with_name("acme_rs6_cell.urdf")
    shutil.copy(top, as_urdf)
    args = {"mount_height": "0.4"}
    a = SerialRobot.from_urdf(as_urdf, "tool0", OFFSET, k_theta=K_ACME, xacro_args=args)
    plain = SerialRobot.from_urdf(ACME_URDF, "tool0", OFFSET, k_theta=K_ACME)
    Q = rng.uniform(plain.chain.lower, plain.chain.upper, size=(3, 6))
    assert _rel(a.stiffness6(Q), plain.stiffness6(Q)) < 1e-12
    written = tmp_path / "written.urdf"
    text = ACME_URDF.read_text()
    written.write_text(text.replace("<robot ", '<robot xmlns:xacro="http://ros.org/wiki/xacro" ', 1))
    b = SerialRobot.from_urdf(written, "tool0", OFFSET, k_theta=K_ACME)
    assert _rel(b.stiffness6(Q), plain.stiffness6(Q)) == 0.0
    with pytest.raises(
        InputError, match=r"xacro arguments \(mount_height\) given, but the file is not xacro"
    ):
        SerialRobot.from_urdf(written, "tool0", k_theta=1e8, xacro_args=args)


PALLETIZER = Path(__file__).parent / "robots" / "palletizer_4ax.urdf"


def test_a_palletizer_s_parallelogram_mimic_joints_on_the_chain(rng, tmp_path, monkeypatch):
    """Mimic joints ON the chain, each following a joint of the chain (a palletizer's parallelogram
    keeping the flange level): the coordinates are A1..A4, the tool stays level at every
    configuration, and position and K printed by ``model urdf`` equal the independent computation;
    with the mimic joints' own springs given (k5, k6), K includes their compliance
    (their columns by central differences, joint held)."""
    text = PALLETIZER.read_text()
    _, joints = ref.read_joints(text)
    chain = ref.path(joints, "tool0")
    coords = ref.coordinates(joints, chain)
    assert coords == ["joint_a1", "joint_a2", "joint_a3", "joint_a4"]
    lo, hi = _limits(joints, coords)
    Q = rng.uniform(lo, hi, size=(6, 4))
    k = np.array([3e9, 4e9, 2e9, 5e8])
    cfg = tmp_path / "pal_configs.csv"
    ref.write_configs(cfg, joints, coords, Q)
    code, out, err = _run(
        ["model", "urdf", PALLETIZER, "--tip", "tool0", "--tip-offset-mm", ",".join(map(str, OFFSET)),
         "--configs", cfg, "--param", "k_theta=" + ",".join(map(str, k)), "--json"],
        monkeypatch,
    )  # fmt: skip
    assert code == 0, err
    for rec, q in zip(json.loads(out), Q, strict=True):
        p, K, K6, _ = _reference(joints, chain, coords, q, k)
        _, R = ref.tip_pose_mm(joints, chain, coords, q, OFFSET)
        np.testing.assert_allclose(R[:, 2], [0.0, 0.0, -1.0], atol=1e-12)  # level: tool0 points down
        assert _rel(rec["position"], p) < 1e-12 and _rel(rec["K"], K) < TOL
        assert rec["K6"] is None and K6 is None  # four joints
    k_m = np.array([8e8, 6e8])  # joint_a4_level_3, joint_a4_level_2 (chain order)
    robot = SerialRobot.from_urdf(PALLETIZER, "tool0", OFFSET, k_theta=[*k, *k_m])
    assert robot.chain.mimic_names == ("joint_a4_level_3", "joint_a4_level_2")
    for q in Q:
        J = ref.jacobian_fd(joints, chain, coords, q, OFFSET)
        C = J @ np.diag(1.0 / k) @ J.T
        for name, km in zip(robot.chain.mimic_names, k_m, strict=True):
            j = ref.joint_column_fd(joints, chain, coords, q, OFFSET, name)
            C += np.outer(j, j) / km
        assert _rel(robot.stiffness3(q), np.linalg.inv(C[:3, :3])) < TOL
