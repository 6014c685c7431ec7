"""The test-bed's hexapod: its 6x6 field, its campaign description, its scene."""

from __future__ import annotations

from importlib.resources import files

import numpy as np
import pytest

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


def test_platform_robot_needs_a_turning_platform():
    with pytest.raises(ValueError, match="dim = 6 legs TOML"):
        platform_robot(LegRobot.from_toml(ROBOTS / "delta.toml"), "legs", "legs")


def test_hexapod_scene_sees_both_boards_over_the_platforms_workspace():
    P = np.array([[x, y, z] for z in (260.0, 340.0) for y in (-50.0, 50.0) for x in (-50.0, 50.0)])
    hexapod_scene().check_visible(P, slack_mm=2.0)
    with pytest.raises(ValueError, match="leaves the image"):
        hexapod_scene().check_visible([[0.0, 0.0, 900.0]])
