"""Robot descriptions as published, from the command line (issue 29): ``--base``, ``--xacro-arg``,
``--package-path`` and ``--links`` of ``stiffmap model urdf`` / ``stiffmap fit urdf``, and each
description that cannot be modelled answered as one line naming the file and the element.

What the library computes from these descriptions is checked against an independent NumPy
computation in ``test_models_robots.py`` and ``test_models_links.py``; here the command line
reaches it: its --json equals that independent computation (``helpers.urdf_reference``) for the
arm inside a mobile manipulator, and equals the pre-expanded URDF for a xacro description.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import urdf_reference as ref
from helpers.cli_process import run_in_process as _cli

from stiffmap.models.robot_files import read_links_toml
from stiffmap.models.serial import SerialRobot

ROBOTS = Path(__file__).parent / "robots"
CLUTTERED = ROBOTS / "cluttered_mm.urdf"
XACRO_WS = ROBOTS / "xacro_ws"
ACME_XACRO = XACRO_WS / "acme_description" / "urdf" / "acme_rs6.urdf.xacro"
ACME_URDF = ROBOTS / "acme_rs6.urdf"
OFFSET = (10.0, -20.0, 30.0)  # mm, in the tip frame
K_ARM = (5e5, 4e8, 4e8, 2e8, 5e7, 5e7, 3e7)  # torso lift (N/mm), six arm joints (N*mm/rad)


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _configs(path: Path, joints, coords, Q) -> Path:
    """A configurations file with columns named after the joints, in reverse order (any order)."""
    cols = [f"{c}_{'mm' if joints[c].type == 'prismatic' else 'deg'}" for c in coords][::-1]
    rows = [",".join(["label", *cols])]
    for i, q in enumerate(Q):
        vals = [
            v if joints[c].type == "prismatic" else math.degrees(v) for c, v in zip(coords, q, strict=True)
        ]
        rows.append(",".join([f"c{i + 1}", *(repr(float(v)) for v in vals[::-1])]))
    path.write_text("\n".join(rows) + "\n")
    return path


def _k_text(k) -> str:
    return "k_theta=" + ",".join(f"{v:.17g}" for v in k)


def test_model_urdf_from_a_base_frame_equals_the_independent_computation(tmp_path, monkeypatch, capsys):
    """``--base base_link``: the planar joint of the mobile base above it held, the other arm,
    wheels and floating caster off the chain; the torso lift and the right arm are the chain."""
    links, joints = ref.read_joints(CLUTTERED.read_text())
    chain = ref.path(joints, "r_tool0", "base_link")
    coords = ref.coordinates(joints, chain)
    assert coords == ["torso_lift_joint", *(f"r_joint_{i}" for i in range(1, 7))]
    rng = np.random.default_rng(2901)
    lo = np.array([0.0, -2.9, -1.5, -2.5, -3.0, -2.0, -math.pi])
    hi = np.array([350.0, 2.9, 2.0, 1.0, 3.0, 2.0, math.pi])
    Q = rng.uniform(lo, hi, size=(3, 7))
    cfg = _configs(tmp_path / "configs.csv", joints, coords, Q)
    code, out, err = _cli(
        ["model", "urdf", CLUTTERED, "--base", "base_link", "--tip", "r_tool0", "--tip-offset-mm",
         ",".join(map(str, OFFSET)), "--configs", cfg, "--param", _k_text(K_ARM), "--json"],
        monkeypatch, capsys,
    )  # fmt: skip
    assert code == 0, err
    recs = json.loads(out)
    k = np.array(K_ARM)
    for q, r in zip(Q, recs, strict=True):
        p, _ = ref.tip_pose_mm(joints, chain, coords, q, OFFSET)
        J = ref.jacobian_fd(joints, chain, coords, q, OFFSET)
        C = J @ np.diag(1.0 / k) @ J.T
        assert _rel(r["position"], p) < 1e-9
        assert _rel(r["K"], np.linalg.inv(C[:3, :3])) < 1e-6
        assert _rel(r["K6"], np.linalg.inv(C)) < 1e-6


def test_model_urdf_of_a_xacro_description_equals_its_pre_expanded_urdf(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    cfg = tmp_path / "q.csv"
    cfg.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,20,-30,40,50,60\n-80,35,10,-20,30,-40\n")
    base = ["--tip", "tool0", "--configs", cfg, "--param", "k_theta=4e8,4e8,2e8,5e7,5e7,3e7", "--json"]
    code, plain, err = _cli(["model", "urdf", ACME_URDF, *base], monkeypatch, capsys)
    assert code == 0, err
    code, xa, err = _cli(
        ["model", "urdf", ACME_XACRO, "--xacro-arg", "mount_height=0.4", "--package-path", XACRO_WS, *base],
        monkeypatch, capsys,
    )  # fmt: skip
    assert code == 0, err
    for a, b in zip(json.loads(xa), json.loads(plain), strict=True):
        assert _rel(a["K6"], b["K6"]) < 1e-12
        assert _rel(a["position"], b["position"]) < 1e-12


LINKS = """[[links]]
link = "link_2"
name = "upper"
[links.beam]
length_mm = 270.0
E_MPa = 70000.0
G_MPa = 26000.0
area_mm2 = 1200.0
Iy_mm4 = 9.0e5
Iz_mm4 = 6.0e5
J_mm4 = 1.2e6
"""


def test_model_and_fit_urdf_take_flexible_links(tmp_path, monkeypatch, capsys):
    """--links: the K printed is the robot's with its link spring (the library's, checked against
    a frame FE solution in test_models_links.py); 'fit urdf' names the link's parameters."""
    lf = tmp_path / "LINKS.toml"
    lf.write_text(LINKS)
    cfg = tmp_path / "q.csv"
    cfg.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,20,-30,40,50,60\n")
    k = (4e8, 4e8, 2e8, 5e7, 5e7, 3e7)
    code, out, err = _cli(
        ["model", "urdf", ACME_URDF, "--tip", "tool0", "--links", lf, "--configs", cfg, "--param",
         _k_text(k), "--json"], monkeypatch, capsys,
    )  # fmt: skip
    assert code == 0, err
    robot = SerialRobot.from_urdf(ACME_URDF, "tool0", k_theta=k, links=read_links_toml(lf))
    rigid = SerialRobot.from_urdf(ACME_URDF, "tool0", k_theta=k)
    q = np.radians([10, 20, -30, 40, 50, 60])
    (rec,) = json.loads(out)
    assert _rel(rec["K6"], robot.stiffness6(q)) < 1e-9
    assert _rel(rec["K6"], rigid.stiffness6(q)) > 1e-3  # the link's spring is felt
    assert "E_upper" in robot.param_names()


@pytest.mark.parametrize(
    "args, element",
    [
        (["--tip", "caster", "--base", "base_link"],
         "joint 'caster_joint' (on the chain from 'base_link' to 'caster') is floating"),
        (["--tip", "r_tool0"], "joint 'base_planar' (on the chain from 'odom' to 'r_tool0') is planar"),
        (["--tip", "r_tool0", "--base", "l_arm_base"],
         "tip frame 'r_tool0' is not below base frame 'l_arm_base'"),
    ],
)  # fmt: skip
def test_descriptions_that_cannot_be_modelled_are_one_line_from_the_command_line(
    tmp_path, monkeypatch, capsys, args, element
):
    cfg = tmp_path / "q.csv"
    cfg.write_text("q1_deg\n0\n")
    code, out, err = _cli(
        ["model", "urdf", CLUTTERED, *args, "--configs", cfg, "--param", "k_theta=1e8"], monkeypatch, capsys
    )
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert f"{CLUTTERED}: " in lines[0] and element in lines[0], lines[0]


def test_mimic_loops_unresolved_xacro_and_bad_link_compliances_are_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    cfg = tmp_path / "q.csv"
    cfg.write_text("q1_deg\n0\n")
    loop = tmp_path / "loop.urdf"
    loop.write_text(
        CLUTTERED.read_text().replace(
            '<limit lower="0" upper="0.04"',
            '<mimic joint="r_finger_right_joint"/><limit lower="0" upper="0.04"',
            1,
        )
    )
    bad_links = tmp_path / "LINKS.toml"
    bad_links.write_text(
        '[[links]]\nlink = "link_3"\ncompliance = [[1e-4,0,0,0,0,0],[0,1e-4,0,0,0,0],[0,0,1e-4,0,0,0],'
        "[0,0,0,-1e-8,0,0],[0,0,0,0,1e-8,0],[0,0,0,0,0,1e-8]]\n"
    )
    alone = tmp_path / ACME_XACRO.name  # outside any package: no workspace to search
    alone.write_text(ACME_XACRO.read_text())
    cases = [
        ([loop, "--base", "base_link", "--tip", "r_finger_right"], f"{loop}: ",
         "mimic loop r_finger_right_joint"),
        ([alone, "--tip", "tool0", "--xacro-arg", "mount_height=0.4"], f"{alone}: ",
         "$(find acme_description): no package 'acme_description'"),
        ([ACME_XACRO, "--tip", "tool0", "--package-path", XACRO_WS], f"{ACME_XACRO}: ",
         "argument 'mount_height' has no value: give it with --xacro-arg mount_height=VALUE"),
        ([ACME_URDF, "--tip", "tool0", "--links", bad_links], f"{bad_links}: ",
         "links[1].compliance: the compliance is not positive"),
    ]  # fmt: skip
    for args, source, element in cases:
        code, out, err = _cli(
            ["model", "urdf", *args, "--configs", cfg, "--param", "k_theta=1e8"], monkeypatch, capsys
        )
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
        assert source in lines[0] and element in lines[0], lines[0]
