"""Planning a simulated vision campaign: its settings, its images, and the disk space they need."""

from __future__ import annotations

import dataclasses
from collections import namedtuple

import numpy as np
import pytest
from helpers.board_scenes import scaled_camera

from stiffmap.camera import reference_camera
from stiffmap.campaign.simulated import write_campaign
from stiffmap.errors import InputError
from stiffmap.loads import paper9
from stiffmap.models.delta import DeltaRobot
from stiffmap.models.presets import paper48
from stiffmap.sim import plan as sim_plan
from stiffmap.sim.plan import BYTES_PER_PIXEL, image_bytes, plan_simulation, vision_config
from stiffmap.sim.robot import delta_robot


def test_vision_config_from_a_users_choices():
    P = paper48()[[0, 21]]
    cfg = vision_config(delta_robot({"k_theta": 3e5}), P, paper9(), repeatability_mm=0.05, seed=4)
    assert cfg.robot.model == "delta" and cfg.robot.params["k_theta"] == 3e5
    assert cfg.robot.repeatability_mm == 0.05 and cfg.seed == 4 and cfg.repeats == 3
    assert cfg.scene.camera.image_size == reference_camera().image_size
    np.testing.assert_allclose(
        cfg.robot.stiffness(P), DeltaRobot(k_theta=3e5).stiffness(P), rtol=1e-12
    )  # N/mm
    assert cfg.photometry.read_noise_dn > 0 and cfg.gain_jitter == 0.03
    # A rotational stiffness makes a 6x6 field at the tool point; no noise, no illumination change.
    cfg6 = vision_config(
        delta_robot(), P, paper9(), rot_stiffness_nmm_per_rad=5e4, load_point_mm=(0, 0, -25), noise=False
    )
    K6 = cfg6.robot.stiffness(P)
    assert K6.shape == (2, 6, 6)
    np.testing.assert_allclose(K6[:, 3:, 3:], np.broadcast_to(5e4 * np.eye(3), (2, 3, 3)))  # N*mm/rad
    assert cfg6.robot.load_point_mm == (0.0, 0.0, -25.0)
    assert cfg6.photometry.read_noise_dn == 0 and cfg6.gain_jitter == 0 and cfg6.offset_jitter_dn == 0
    with pytest.raises(InputError, match="k_rot_nmm_per_rad must be a positive number"):
        vision_config(delta_robot(), P, paper9(), rot_stiffness_nmm_per_rad=float("inf"))
    with pytest.raises(InputError, match="image_format must be png or jpeg"):
        vision_config(delta_robot(), P, paper9(), image_format="tiff")


def test_plan_counts_the_images_and_names_an_unreachable_position(tmp_path):
    cfg = vision_config(delta_robot(), paper48()[[0, 47]], paper9()[:3], repeats=2)
    sim = plan_simulation(cfg, tmp_path / "new" / "dir")  # need not exist yet
    assert sim.n_images == len(sim.plan.jobs) == 2 * 2 * 3 * 2  # unloaded + loaded per case
    # The calibration views (20 by default) are images too.
    assert sim.n_calibration_views == cfg.calibration_views == 20
    assert sim.bytes_needed == image_bytes(cfg, sim.n_images + 20)
    truth_only = plan_simulation(cfg, tmp_path, render_images=False)
    assert truth_only.n_images == 0 and truth_only.n_calibration_views == 0 and truth_only.bytes_needed == 0
    far = vision_config(delta_robot(), [[0.0, 0.0, -310.0], [0.0, 0.0, -900.0]], paper9())
    with pytest.raises(InputError, match=r"position 2 \(0, 0, -900\) mm: the robot model has no stiffness"):
        plan_simulation(far, tmp_path)


def test_the_disk_check_refuses_before_writing(tmp_path, monkeypatch):
    cfg = vision_config(delta_robot(), paper48()[[21]], paper9(), repeats=1, calibration_views=0)
    need = image_bytes(cfg, 18)
    w, h = reference_camera().image_size
    assert need == pytest.approx(18 * w * h * BYTES_PER_PIXEL["png"], rel=1e-15)  # bytes
    colour = vision_config(
        delta_robot(), paper48()[[21]], paper9(), repeats=1, colour=True, image_format="jpeg"
    )
    assert image_bytes(colour, 18) == pytest.approx(
        18 * w * h * np.sqrt(3) * BYTES_PER_PIXEL["jpeg"], rel=1e-15
    )
    Usage = namedtuple("Usage", "total used free")
    # 95 % of the free space at most: refused just above, accepted just below.
    free = int(need / 0.95) - 1000
    monkeypatch.setattr(sim_plan.shutil, "disk_usage", lambda path: Usage(0, 0, free))
    out = tmp_path / "sim"
    with pytest.raises(InputError) as e:
        plan_simulation(cfg, out, advice="use fewer --repeats")
    assert str(e.value) == (
        f"{out}: 18 images need about {need / 1e9:.1f} GB but only {free / 1e9:.1f} GB are free; "
        "use fewer --repeats"
    )
    assert not out.exists()
    monkeypatch.setattr(sim_plan.shutil, "disk_usage", lambda path: Usage(0, 0, free + 2000))
    assert plan_simulation(cfg, out).n_images == 18
    # With the calibration views, 18 + 5 images must fit.
    with pytest.raises(InputError, match="23 images need about"):
        plan_simulation(dataclasses.replace(cfg, calibration_views=5), out)


@pytest.mark.parametrize("image_format", ["png", "jpeg"])
def test_the_estimate_against_the_images_written(tmp_path, image_format):
    # Two 2592x1944 images of the default scene (position 22, the 0.5 kg load along +y), with
    # the true camera (a calibration view, 2.3 MB as PNG, is within the same estimate).
    cfg = vision_config(
        delta_robot(),
        paper48()[[21]],
        paper9()[:1],
        repeats=1,
        image_format=image_format,
        calibration_views=0,
    )
    sim = plan_simulation(cfg, tmp_path / "sim")
    written = write_campaign(tmp_path / "sim", cfg, plan=sim.plan)
    on_disk = sum(p.stat().st_size for p in (tmp_path / "sim" / "images").rglob("*.*"))
    assert written.n_images == sim.n_images == 2 and written.bytes_written == on_disk
    # Never much below what is written (the check must not let a disk fill), nor far above.
    assert 1.0 <= sim.bytes_needed / on_disk <= 1.5, (sim.bytes_needed, on_disk)


def test_a_smaller_camera_needs_less():
    small = scaled_camera(reference_camera(), 0.25)
    cfg = vision_config(delta_robot(), paper48()[[21]], paper9(), small, repeats=1)
    assert image_bytes(cfg, 18) == pytest.approx(18 * 648 * 486 * BYTES_PER_PIXEL["png"], rel=1e-15)
