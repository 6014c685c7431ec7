"""A campaign on a user's own robot description (issue 29): ``stiffmap simulate --robot FILE`` on
a URDF nobody wrote for the test-bed, then the model step of ``stiffmap run`` recovers its joint
stiffnesses within 2 %, as it does for the test-bed's arm (test_campaign_urdf.py).

The robot: the right arm of a cluttered mobile manipulator (tests/robots/cluttered_mm.urdf),
from its base_link (the planar joint of the mobile base above it held), the torso lift a
prismatic coordinate, 12 joint configurations with named columns. A xacro description with a
flexible link goes into a campaign that needs neither xacro nor its packages.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from stiffmap.campaign.robot import campaign_model, campaign_positions
from stiffmap.campaign.runner import fit_and_evaluate_model
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import DB_NAME, Store, to_json
from stiffmap.campaign.truth import load_truth
from stiffmap.cli.main import main as stiffmap
from stiffmap.errors import InputError
from stiffmap.models.io import read_configuration_rows
from stiffmap.models.serial import SerialRobot

ROBOTS = Path(__file__).parent / "robots"
CLUTTERED = ROBOTS / "cluttered_mm.urdf"
CONFIGS = ROBOTS / "cluttered_mm_configs.csv"
XACRO_WS = ROBOTS / "xacro_ws"
ACME_XACRO = XACRO_WS / "acme_description" / "urdf" / "acme_rs6.urdf.xacro"
K_TRUE = (1e2, 2e7, 1.6e7, 1.2e7, 5e6, 4e6, 3e6)  # the torso lift (N/mm), six arm joints (N*mm/rad)


@pytest.fixture(scope="module")
def own_campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("own") / "campaign"
    code = stiffmap(
        ["simulate", str(root), "--robot", str(CLUTTERED), "--base", "base_link", "--tip", "r_tool0",
         "--tip-offset-mm", "40,30,100", "--configs", str(CONFIGS), "--param",
         "k_theta=" + ",".join(f"{k:g}" for k in K_TRUE), "--truth-only", "--json"]
    )  # fmt: skip
    assert code in (0, None)
    return root


def test_the_campaign_is_self_contained_and_its_truth_is_the_model(own_campaign):
    root = own_campaign
    spec = load_spec(root)
    assert spec.robot.keys["urdf"] == "robot.urdf" and spec.robot.keys["base_frame"] == "base_link"
    assert (root / "robot.urdf").read_text() == CLUTTERED.read_text()
    model = campaign_model(spec, root)
    assert model.chain.joint_names[0] == "torso_lift_joint"
    assert (model.chain.base_frame, model.chain.root_frame) == ("base_link", "odom")
    # The configurations as campaign.toml's positions.q_deg: degrees, the lift in mm.
    Q_file, _ = read_configuration_rows(CONFIGS, model.chain)
    np.testing.assert_allclose(model.configurations, Q_file, rtol=0, atol=1e-9)
    P = campaign_positions(spec, root)
    np.testing.assert_allclose(P, model.chain.forward_many(Q_file)[0], atol=1e-6)
    np.testing.assert_allclose(model.evaluate(P).K, np.array(load_truth(root).K), rtol=1e-9)


def test_run_recovers_the_joint_stiffnesses_of_a_users_robot(own_campaign):
    """Displacements as the vision path stores them (translations and rotations, base frame,
    1-2 um and 5 urad), 12 positions x 9 loads x 3 repeats: every joint within 2 %."""
    root = own_campaign
    spec = load_spec(root)
    truth = campaign_model(spec, root)
    P = campaign_positions(spec, root)
    ik = truth.configurations_for(P)
    loads = spec.loads.resolve(spec.g)
    rng = np.random.default_rng(29)
    sd = np.array([1e-3, 1e-3, 2e-3, 5e-6, 5e-6, 5e-6])
    cov = np.diag(sd**2)
    with Store(root / DB_NAME) as st:
        for p, (xyz, q) in enumerate(zip(P, ik.q, strict=True), start=1):
            disp = []
            for ld, load in enumerate(loads, start=1):
                d_true = truth.deflection(q, np.concatenate([load.force, np.zeros(3)]))
                for r in range(1, 4):
                    disp.append(
                        {
                            "position": p, "load": ld, "repeat": r, "unloaded": "u", "loaded": "l",
                            "frame": "base", "d": to_json(d_true + rng.normal(scale=sd)), "cov": to_json(cov),
                            "status": "ok", "params_hash": "t", "version": "t",
                        }
                    )  # fmt: skip
            stiff = {
                "position": p, "x": xyz[0], "y": xyz[1], "z": xyz[2], "status": "ok",
                "inputs_hash": "t", "params_hash": "t", "version": "t",
            }  # fmt: skip
            st.save_position(p, displacements=disp, repeat_stats=[], stiffness=stiff)
        start = spec.model_copy(update={"robot": spec.robot.model_copy(
            update={"params": {k: 3 * v for k, v in spec.robot.params.items()}})})  # fmt: skip
        problems = fit_and_evaluate_model(st, start, root)
        fit = st.model_fit("stiffness")
        rows = st.model_stiffness_rows()
    assert fit.status == "ok", fit.error
    assert not [p for p in problems if "outside the model" in p], problems
    for i, k_true in enumerate(K_TRUE, start=1):
        k, s = fit.params[f"k{i}"], fit.std[f"k{i}"]
        assert abs(k - k_true) < 4 * s, (i, k, k_true, s)
        assert abs(k / k_true - 1) < 0.02 and s / k_true < 0.02, (i, k, s)
    assert len(rows) == 12 and all(r.valid for r in rows)


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


def test_a_xacro_description_with_a_flexible_link_makes_a_campaign_without_xacro(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    links = tmp_path / "LINKS.toml"
    links.write_text(LINKS)
    cfg = tmp_path / "q.csv"
    cfg.write_text("joint_1_deg,joint_2_deg,joint_3_deg,joint_4_deg,joint_5_deg,joint_6_deg\n"
                   "0,20,10,30,60,0\n15,10,20,-30,50,40\n-15,25,0,20,70,-40\n")  # fmt: skip
    root = tmp_path / "campaign"
    code = stiffmap(
        ["simulate", str(root), "--robot", str(ACME_XACRO), "--xacro-arg", "mount_height=0.4",
         "--package-path", str(XACRO_WS), "--links", str(links), "--tip", "tool0", "--configs", str(cfg),
         "--param", "k_theta=2e7,1.6e7,1.2e7,5e6,4e6,3e6", "--truth-only", "--json"]
    )  # fmt: skip
    assert code in (0, None)
    spec = load_spec(root)
    assert "xacro" not in spec.robot.keys["urdf"] and "xacro_args" not in spec.robot.keys
    assert spec.robot.keys["links"] == "links.toml" and spec.robot.params["E_upper"] == 7e4
    model = campaign_model(spec, root)  # no package folder, no xacro argument: the expanded URDF
    assert model.link_param_names() == ("E_upper", "G_upper")
    P = campaign_positions(spec, root)
    np.testing.assert_allclose(model.evaluate(P).K, np.array(load_truth(root).K), rtol=1e-9)
    rigid = campaign_model(spec.model_copy(update={"robot": spec.robot.model_copy(
        update={"params": {**spec.robot.params, "E_upper": 7e10, "G_upper": 2.6e10}})}), root)  # fmt: skip
    assert np.max(np.abs(rigid.evaluate(P).K / model.evaluate(P).K - 1)) > 0.01  # the link is felt


@pytest.mark.parametrize(
    "args, message",
    [
        (["--robot", "arm6", "--tip", "tool0"], "--tip: for a robot of your own (--robot FILE.urdf"),
        (["--robot", "nowhere.urdf"], "--robot nowhere.urdf: no such file"),
        (["--robot", str(CLUTTERED), "--base", "base_link", "--configs", str(CONFIGS)], "--tip is required"),
        (["--robot", str(CLUTTERED), "--base", "base_link", "--tip", "r_tool0", "--param", "k_theta=1e7"],
         "--positions: give the positions"),
        (["--robot", str(CLUTTERED), "--base", "l_arm_base", "--tip", "r_tool0", "--configs", str(CONFIGS)],
         "tip frame 'r_tool0' is not below base frame 'l_arm_base'"),
    ],
)  # fmt: skip
def test_a_robot_of_ones_own_that_cannot_be_simulated_is_one_line(
    tmp_path, monkeypatch, capsys, args, message
):
    from helpers.cli_process import run_in_process

    code, out, err = run_in_process(
        ["simulate", tmp_path / "out", *args, "--truth-only"], monkeypatch, capsys
    )
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert message in lines[0], lines[0]
    assert not (tmp_path / "out").exists()


def test_a_configuration_at_a_joint_singularity_is_named_by_its_position(tmp_path, monkeypatch, capsys):
    # The simulated field is K6, which a wrist singularity (q5 = 0) has not ('model urdf' gives K
    # there with a note): one line naming the position (the configuration's row, its measured point
    # from the chain's forward kinematics) and the reason; was the reason alone, no position.
    from helpers.cli_process import run_in_process  # as the test above

    arm6 = files("stiffmap.models") / "robots" / "arm6.urdf"
    cfg = tmp_path / "configs.csv"
    cfg.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,10,-40,0,40,0\n0,0,-30,0,0,0\n")
    args = ["--robot", arm6, "--tip", "tool0", "--configs", cfg, "--param", "k_theta=4e8", "--truth-only"]
    code, out, err = run_in_process(["simulate", tmp_path / "out", *args], monkeypatch, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    p = SerialRobot.from_urdf(arm6, "tool0", k_theta=4e8).chain.forward(np.radians([0, 0, -30, 0, 0, 0]))[0]
    at = ", ".join(f"{v:g}" for v in p)
    assert lines[0].startswith(f"error: position 2 ({at}) mm: the robot model has no stiffness there")
    assert "(singular: joints joint_4 and joint_6 move the tip alike (wrist singularity)" in lines[0]
    assert not (tmp_path / "out" / "campaign.toml").exists()


def test_campaign_toml_reads_a_xacro_description_with_its_packages_in_the_campaign_folder(
    tmp_path, monkeypatch
):
    """urdf = a .xacro, xacro_args, package_paths relative to the campaign folder (not the working
    directory): the K of the pre-expanded URDF; a wrong argument named by its key."""
    import shutil

    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.chdir(tmp_path)
    root = tmp_path / "campaign"
    shutil.copytree(XACRO_WS, root / "ws")
    robot = (
        '[robot]\nmodel = "urdf"\nurdf = "ws/acme_description/urdf/acme_rs6.urdf.xacro"\n'
        'xacro_args = {mount_height = "0.4"}\npackage_paths = ["ws"]\ntip_frame = "tool0"\n'
        "params = {k1 = 1e7, k2 = 1e7, k3 = 1e7, k4 = 1e7, k5 = 1e7, k6 = 1e7}\n"
    )
    rest = (
        "[positions]\nq_deg = [[0.0, 20.0, 10.0, 30.0, 60.0, 0.0], [15.0, 10.0, 20.0, -30.0, 50.0, 40.0]]\n"
        '[camera]\nfile = "camera.json"\n[targets.mobile]\nboard = "6x5"\nsquare_mm = 10.0\n'
        '[loads]\npreset = "paper9"\n'
    )
    (root / "campaign.toml").write_text(f'name = "x"\nkind = "vision"\n{robot}{rest}')
    spec = load_spec(root)
    model = campaign_model(spec, root)
    plain = SerialRobot.from_urdf(ROBOTS / "acme_rs6.urdf", "tool0", k_theta=1e7)
    Q = np.radians([[0.0, 20.0, 10.0, 30.0, 60.0, 0.0], [15.0, 10.0, 20.0, -30.0, 50.0, 40.0]])
    np.testing.assert_allclose(model.stiffness6(Q), plain.stiffness6(Q), rtol=1e-12)
    (root / "campaign.toml").write_text(f'name = "x"\nkind = "vision"\n{robot.replace("0.4", "high")}{rest}')
    with pytest.raises(InputError) as e:
        campaign_model(load_spec(root), root)
    assert "origin xyz" in str(e.value) and "\n" not in str(e.value), str(e.value)
