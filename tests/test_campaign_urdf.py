"""A serial robot's campaign from its URDF: the spec, the test-bed's arm, the joint fit of `stiffmap run`."""

from __future__ import annotations

from importlib.resources import files

import numpy as np
import pytest

from stiffmap.campaign.robot import campaign_model, campaign_positions, fitted_names
from stiffmap.campaign.runner import fit_and_evaluate_model
from stiffmap.campaign.spec import load_spec, parse_spec
from stiffmap.campaign.store import DB_NAME, Store, to_json
from stiffmap.campaign.truth import load_truth
from stiffmap.cli.main import main as stiffmap
from stiffmap.errors import InputError
from stiffmap.models import DeltaRobot, arm6

_BASE = """
[camera]
file = "camera.json"
[targets.mobile]
board = "6x5"
square_mm = 10.0
[loads]
preset = "paper9"
"""


@pytest.mark.parametrize(
    "robot, positions, message",
    [
        ('model = "urdf"\ntip_frame = "tool0"', "list = [[500.0, 0.0, 400.0]]", "needs robot.urdf"),
        (
            'model = "urdf"\nurdf = "r.urdf"\ntip_frame = "tool0"\nparams = {k_theta = 1e6}',
            "list = [[1.0, 0.0, 0.0]]",
            "'k_theta' is not a joint stiffness",
        ),
        (
            'model = "delta"\ntip_frame = "tool0"',
            "list = [[0.0, 0.0, -300.0]]",
            'robot.tip_frame is for model = "urdf"',
        ),
        ('model = "delta"', "q_deg = [[0.0, 10.0]]", "positions.q_deg gives joint configurations"),
        (
            'model = "urdf"\nurdf = "r.urdf"\ntip_frame = "t"',
            "q_deg = [[0.0, 10.0], [1.0]]",
            r"q_deg\[1\] has 1 joint values",
        ),
        ('model = "legs"', "list = [[0.0, 0.0, -300.0]]", "needs robot.legs"),
    ],
)
def test_robot_spec_mistakes_are_named(robot, positions, message):
    with pytest.raises(InputError, match=message):
        parse_spec(f'kind = "vision"\n[robot]\n{robot}\n[positions]\n{positions}\n{_BASE}')


@pytest.fixture(scope="module")
def arm_campaign(tmp_path_factory):
    """`stiffmap simulate --robot arm6 --truth-only`: the spec, the arm's URDF and the truth, no images."""
    root = tmp_path_factory.mktemp("arm") / "campaign"
    assert stiffmap(["simulate", str(root), "--robot", "arm6", "--truth-only", "--json"]) in (0, None)
    return root


def test_simulated_arm_campaign_is_self_contained_and_its_truth_is_the_model(arm_campaign):
    root = arm_campaign
    spec = load_spec(root)
    assert spec.robot.model == "urdf" and (root / spec.robot.urdf).is_file()
    assert spec.loads.point_mm == pytest.approx(arm6.LOAD_POINT_MM)
    model = campaign_model(spec, root)
    assert model.params() == pytest.approx({f"k{i + 1}": k for i, k in enumerate(arm6.K_THETA)})
    truth = load_truth(root)
    P = campaign_positions(spec, root)
    np.testing.assert_allclose(P, arm6.positions20())
    ik = model.configurations_for(P)
    assert ik.reachable.all()
    # The test-bed's 6x6 field is the model's stiffness at the inverse-kinematics configurations,
    # and the K it says a campaign identifies (forces at loads.point_mm) is the model's map.
    K6 = np.array([model.stiffness6(q) for q in ik.q])
    K3_true = np.array(truth.K)
    lever = np.asarray(arm6.LOAD_POINT_MM)
    S = np.array([[0.0, -lever[2], lever[1]], [lever[2], 0.0, -lever[0]], [-lever[1], lever[0], 0.0]])
    C = np.linalg.inv(K6)
    np.testing.assert_allclose(K3_true, np.linalg.inv(C[:, :3, :3] + C[:, :3, 3:] @ S), rtol=1e-9)
    np.testing.assert_allclose(model.evaluate(P).K, K3_true, rtol=1e-9)


def test_run_fits_the_joint_stiffnesses_to_the_displacements(arm_campaign):
    """The model step of `stiffmap run` on displacements as the vision path stores them: the
    deflection of each load case (translations and rotations, base frame) with its covariance."""
    root = arm_campaign
    spec = load_spec(root)
    truth_model = campaign_model(spec, root)
    P = campaign_positions(spec, root)
    ik = truth_model.configurations_for(P)
    loads = spec.loads.resolve(spec.g)
    lever = np.asarray(spec.loads.point_mm)
    rng = np.random.default_rng(7)
    sd = np.array([1e-3, 1e-3, 2e-3, 5e-6, 5e-6, 5e-6])  # 1-2 um and 5 urad, as one camera measures
    cov = np.diag(sd**2)
    store_path = root / DB_NAME
    with Store(store_path) as st:
        for p, (xyz, q) in enumerate(zip(P, ik.q, strict=True), start=1):
            disp = []
            for ld, load in enumerate(loads, start=1):
                w = np.concatenate([load.force, np.cross(lever, load.force)])
                d_true = truth_model.deflection(q, w)
                for r in range(1, 4):
                    d = d_true + rng.normal(scale=sd)
                    disp.append(
                        {
                            "position": p, "load": ld, "repeat": r, "unloaded": "u", "loaded": "l",
                            "frame": "base", "d": to_json(d), "cov": to_json(cov), "status": "ok",
                            "params_hash": "t", "version": "t",
                        }
                    )  # fmt: skip
            stiff = {
                "position": p, "x": xyz[0], "y": xyz[1], "z": xyz[2], "status": "ok",
                "inputs_hash": "t", "params_hash": "t", "version": "t",
            }  # fmt: skip
            st.save_position(p, displacements=disp, repeat_stats=[], stiffness=stiff)
        # Start the fit away from the truth: it is linear, the start must not matter.
        problems = fit_and_evaluate_model(st, spec.model_copy(update={"robot": spec.robot.model_copy(
            update={"params": {k: 2 * v for k, v in spec.robot.params.items()}})}), root)  # fmt: skip
        fit = st.model_fit("stiffness")
        rows = st.model_stiffness_rows()
    assert fit.status == "ok", fit.error
    assert not [p for p in problems if "outside the model" in p]
    est = fit.params
    std = fit.std
    for i, k_true in enumerate(arm6.K_THETA, start=1):
        k, s = est[f"k{i}"], std[f"k{i}"]
        assert abs(k - k_true) < 4 * s, (i, k, k_true, s)
        assert s / k_true < 0.02  # 540 displacements of this precision pin each joint within 2 %
    assert len(rows) == 20 and all(r.valid for r in rows)
    # The model's K beside the measured one: what forces hung at loads.point_mm see.
    C = truth_model.with_params(**est).compliance6(ik.q[0])
    S = np.array([[0.0, -lever[2], lever[1]], [lever[2], 0.0, -lever[0]], [-lever[1], lever[0], 0.0]])
    np.testing.assert_allclose(rows[0].K, np.linalg.inv(C[:3, :3] + C[:3, 3:] @ S), rtol=1e-9)


def test_a_robot_described_by_its_legs_is_a_campaign_model(tmp_path):
    """[robot] model = "legs": the TOML next to campaign.toml is the model, fitted by its [params]."""
    toml = (files("stiffmap.models") / "robots" / "delta.toml").read_text()
    (tmp_path / "delta_legs.toml").write_text(toml)
    text = (
        'kind = "vision"\n[robot]\nmodel = "legs"\nlegs = "delta_legs.toml"\n'
        "[positions]\nlist = [[0.0, 0.0, -300.0]]\n" + _BASE
    )
    spec = parse_spec(text)
    model = campaign_model(spec, tmp_path)
    np.testing.assert_allclose(
        model.stiffness([[0.0, 0.0, -300.0]]),
        DeltaRobot().stiffness([[0.0, 0.0, -300.0]]),
        rtol=1e-9,
        atol=1e-9,
    )
    assert fitted_names(spec, model) == tuple(model.param_names())
    missing = r"nowhere\.toml: no such file \(named by campaign\.toml robot\.legs\)"
    with pytest.raises(InputError, match=missing):
        campaign_model(parse_spec(text.replace("delta_legs.toml", "nowhere.toml")), tmp_path)
