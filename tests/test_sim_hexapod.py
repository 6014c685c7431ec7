"""The test-bed's hexapod: its 6x6 field, its campaign description, its scene."""

from __future__ import annotations

import json
from importlib.resources import files

import numpy as np
import pytest
from helpers.cli_process import run_in_process as _cli

from stiffmap.campaign.platform import hung_force_stiffness, is_platform, level_poses
from stiffmap.campaign.robot import campaign_model
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import DB_NAME, Store
from stiffmap.kinds.parallel import HEXAPOD_TESTBED_K
from stiffmap.models.legs import LegRobot
from stiffmap.sim.robot import LEGS_NAME, PlatformField, platform_robot
from stiffmap.sim.scene import hexapod_scene

ROBOTS = files("stiffmap.models") / "robots"


@pytest.fixture(scope="module")
def hexapod():
    return LegRobot.from_toml(ROBOTS / "hexapod.toml").with_params(k_leg2=300.0, k_leg5=800.0)


def test_platform_field_is_K6_at_level_poses_and_turns_under_an_offset_load(hexapod):
    P = np.array([[0.0, 0.0, 300.0], [30.0, -20.0, 280.0]])
    vr = platform_robot(hexapod, "legs", "legs", load_point_mm=(40.0, 0.0, -60.0))
    K = vr.stiffness(P)
    np.testing.assert_array_equal(K, hexapod.stiffness6(np.c_[P, np.zeros((2, 3))]))
    F = np.array([0.0, 5.0, -20.0])
    u, w = vr.compliant_motion(K[1], F)
    d = np.linalg.solve(K[1], np.r_[F, np.cross([40.0, 0.0, -60.0], F)])
    np.testing.assert_allclose(np.r_[u, w], d, rtol=1e-12)
    assert np.linalg.norm(w) > 1e-5  # the platform turns: a 6x6 field, not a 3x3 one
    assert vr.model == "legs" and vr.spec == {"legs": LEGS_NAME}
    assert vr.files[LEGS_NAME] == str(hexapod.source)
    assert vr.params == {k: float(v) for k, v in hexapod.params().items()}


def test_platform_field_names_a_position_the_legs_cannot_reach(hexapod):
    with pytest.raises(ValueError, match=r"\[0\.0, 0\.0, 600\.0\] mm: unreachable: leg \d \(leg\d\)"):
        PlatformField(hexapod)([[0.0, 0.0, 600.0]])


def test_platform_robot_needs_a_platform_in_space():
    with pytest.raises(ValueError, match="dim = 6 or dim = 3 legs TOML"):
        platform_robot(LegRobot.from_toml(ROBOTS / "3prr.toml"), "legs", "legs")


def test_hexapod_scene_sees_both_boards_over_the_platforms_workspace():
    P = np.array([[x, y, z] for z in (260.0, 340.0) for y in (-50.0, 50.0) for x in (-50.0, 50.0)])
    hexapod_scene().check_visible(P, slack_mm=2.0)
    with pytest.raises(ValueError, match="leaves the image"):
        hexapod_scene().check_visible([[0.0, 0.0, 900.0]])


@pytest.mark.slow  # 4-6 s: the test-bed's truth of two positions
def test_simulate_robot_hexapod_writes_a_legs_campaign_with_its_true_K(monkeypatch, capsys, tmp_path):
    # The truth K of each position is that of forces hung 100 mm below the tool point, from the
    # test-bed legs' K6 (campaign.platform.hung_force_stiffness); the campaign's model is the legs
    # robot it copied, built by the registry as stiffmap run builds it.
    out = tmp_path / "hex"
    code, _, err = _cli(
        ["simulate", out, "--robot", "hexapod", "--truth-only", "--select", "1,14"], monkeypatch, capsys
    )
    assert code == 0, err
    spec = load_spec(out / "campaign.toml")
    model = campaign_model(spec, out)
    assert is_platform(model) and spec.robot.model == "legs"
    assert model.params() == {f"k_leg{i}": k for i, k in enumerate(HEXAPOD_TESTBED_K, start=1)}
    truth = json.loads((out / "truth.json").read_text())
    P = np.array([p["position"] for p in truth["positions"]])
    np.testing.assert_array_equal(P, [[-40.0, -40.0, 280.0], [0.0, 0.0, 320.0]])
    K6 = model.stiffness6(level_poses(P))
    for p, k6 in zip(truth["positions"], K6, strict=True):
        np.testing.assert_allclose(p["K_tcp"], k6, rtol=1e-12)
        np.testing.assert_allclose(p["K"], hung_force_stiffness(k6, [0.0, 0.0, -100.0]), rtol=1e-10)


@pytest.mark.long
def test_hexapod_campaign_recovers_its_legs(monkeypatch, capsys, tmp_path):
    # simulate then run, four positions, one repeat: the six legs within 1 % and 4 standard errors.
    out = tmp_path / "hex"
    args = ["simulate", out, "--robot", "hexapod", "--select", "1,9,10,18", "--repeats", "1"]
    code, _, err = _cli([*args, "--workers", "2"], monkeypatch, capsys)
    assert code == 0, err
    code, _, err = _cli(["run", out, "--workers", "2"], monkeypatch, capsys)
    # The extra noise the leg fit estimates is a note, not a warning: a good campaign exits 0.
    assert code == 0, err
    assert "note: model fit:" in err and "extra noise" in err, err
    with Store(out / DB_NAME) as st:
        fit = st.model_fit("stiffness")
    assert fit is not None and fit.status == "ok", fit
    for i, k in enumerate(HEXAPOD_TESTBED_K, start=1):
        est, std = fit.params[f"k_leg{i}"], fit.std[f"k_leg{i}"]
        assert abs(est - k) < 0.01 * k and abs(est - k) < 4 * std, (i, est, std)
