"""A campaign measured by two cameras: simulated by the test-bed (a rig), run, against the truth."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_scenes import scaled_camera

from stiffmap.camera import reference_camera
from stiffmap.campaign.runner import run_vision_campaign
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.store import DB_NAME, Store
from stiffmap.campaign.truth import load_truth
from stiffmap.loads import paper9
from stiffmap.rig import camera_path, load_rig
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import default_scene, with_cameras
from stiffmap.sim.testbed import SimConfig

POSITIONS = np.array([[-66.67, 66.67, -310.0]])


@pytest.fixture(scope="module")
def rig_campaign(tmp_path_factory):
    """Two cameras 60 degrees apart (the true rig, 3/4 of the reference camera's pixels per side:
    at half, the 10 mm squares seen 35 degrees obliquely are too small for the second camera to
    find the boards), one position x 6 loads."""
    scene = with_cameras(default_scene(scaled_camera(reference_camera(), 0.75)), 2, distance_scale=1.2)
    cfg = SimConfig(
        scene=scene,
        robot=delta_robot(),
        positions=POSITIONS,
        loads=tuple(paper9())[:6],
        repeats=1,
        seed=11,
        robot_stays=True,
        calibration_views=0,
    )
    out = tmp_path_factory.mktemp("rig") / "c"
    write_campaign(out, cfg)
    return out


def _K(out):
    with Store(out / DB_NAME) as store:
        rows = store.stiffness_rows()
        meas = store.measurement_rows()
    return rows, meas


def test_a_two_camera_campaign_recovers_K_and_keeps_each_cameras_outcome(rig_campaign):
    out = rig_campaign
    rig = load_rig(out / "rig.json")
    summary = run_vision_campaign(out)
    assert not summary.failures
    rows, meas = _K(out)
    truth = load_truth(out)
    for r, K_true in zip(rows, truth.K, strict=True):
        assert r.status == "ok"
        K = r.K
        # Both cameras see each board; depth comes from the other camera's side view.
        # Measured 0.4 % (seed 11); 1.5 % leaves room for other seeds' noise, not for a wrong frame.
        assert np.linalg.norm(K - K_true) / np.linalg.norm(K_true) < 0.015
    for m in meas:
        per = m.per_camera
        assert [c["name"] for c in per] == list(rig.names)
        assert all(c["ok"] and set(c["boards"]) == {"mobile", "fixed"} for c in per)
        # The stored calibration sensitivity spans the rig's parameters (both cameras and cam2rig).
        assert m.mobile_cal_jac.shape == (6, len(rig.param_names))


def test_an_image_missing_for_one_camera_is_named_and_the_set_measured_by_the_other(rig_campaign):
    out = rig_campaign
    run_vision_campaign(out)
    _, meas = _K(out)
    victim = next(m.image for m in meas if "loaded" in m.image and "unloaded" not in m.image)
    (out / camera_path(victim, "cam2")).unlink()
    summary = run_vision_campaign(out)
    assert not summary.failures
    rows, meas = _K(out)
    assert all(r.status == "ok" for r in rows)
    m = next(m for m in meas if m.image == victim)
    assert m.status == "ok"
    per = {c["name"]: c for c in m.per_camera}
    assert per["cam1"]["ok"] and not per["cam2"]["ok"]
    assert camera_path(victim, "cam2").split("/")[-1] in per["cam2"]["error"]


def test_the_report_shows_each_cameras_residuals(rig_campaign):
    from stiffmap.campaign.spec import load_spec
    from stiffmap.report.campaign import report_data

    out = rig_campaign
    run_vision_campaign(out)
    with Store(out / DB_NAME) as store:
        data = report_data(out, load_spec(out), store, [])
    cams = data.calibration.cameras
    assert [c["name"] for c in cams] == ["cam1", "cam2"]
    for c in cams:
        assert c["seen"] >= c["sets"] - 1 > 0  # every set, but the one a test may have cut
        assert 0 < c["rms_px"] < 0.2
    # cam2's pose: 60 degrees about the vertical from cam1.
    T = np.asarray(cams[1]["cam2rig"])
    assert np.degrees(np.arccos((np.trace(T[:3, :3]) - 1) / 2)) == pytest.approx(60.0, abs=1e-6)
    # The image shown with its boards (the first camera's image of the first measured set): the
    # corners projected from the measured poses fall on the true corners the test-bed rendered.
    bi = data.board_image
    assert bi.scale == 3.0  # 1944 px wide, shown a third
    corners = load_truth(out).corners()
    true = next(c for f, c in corners.items() if f.replace("{camera}", "cam1") == bi.name)
    for board in ("mobile", "fixed"):
        px = bi.corners_px[[b.startswith(board) for b in bi.corner_board]]
        t = true["cameras"]["cam1"][board]["corners_px"]
        d = np.linalg.norm(t[:, None] - px[None], axis=2).min(axis=1)
        assert len(px) == len(t) and d.max() < 0.5, (board, d.max())  # px
    # The set-up summary counts what the store holds: 1 position x (6 loaded + 1 unloaded) sets.
    setup = {s.what: s.value for s in data.setup}
    assert setup["images"] == "7 of 7 measured, 0 failed (1 position)"
    assert setup["load cases"].startswith("6, 1 repeat(s) each: 1: 0.5 kg +y (0, 4.905, 0 N)")


def test_the_exported_measurements_say_what_each_camera_gave(rig_campaign):
    from stiffmap.campaign.export import read_tables

    out = rig_campaign
    run_vision_campaign(out)
    with Store(out / DB_NAME) as store:
        rows = read_tables(store)["measurements"]
    assert rows and all(r["cameras"].startswith("cam1: ") and "; cam2: " in r["cameras"] for r in rows)
