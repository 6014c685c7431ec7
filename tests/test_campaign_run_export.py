"""``run_and_export``: a campaign of either kind run by its runner, then its tables exported."""

from __future__ import annotations

import json

from stiffmap.campaign.run import run_and_export
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.simulated_sensor import write_sensor_campaign
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import DB_NAME
from stiffmap.loads import paper9
from stiffmap.models.presets import paper48, prr3_points22
from stiffmap.models.prr3 import PRR3
from stiffmap.sim.plan import vision_config
from stiffmap.sim.robot import delta_robot


def test_a_sensor_campaign_is_analysed_then_exported(tmp_path):
    write_sensor_campaign(tmp_path, PRR3(), prr3_points22()[[1, 7]], directions=("y",), seed=2)
    done = run_and_export(tmp_path)
    assert done.vision is None and done.sensor.recordings == done.sensor.analysed == 2
    assert done.failures == [] and done.root == tmp_path.resolve()
    assert done.db == tmp_path.resolve() / DB_NAME and done.db.is_file()
    summary = json.loads((done.exports / "summary.json").read_text())
    assert len(summary["sensor_results"]) == 2
    assert (done.exports / "sensor_results.csv").is_file()
    # A second run, with the spec already read, reuses both recordings.
    again = run_and_export(tmp_path, spec=load_spec(tmp_path))
    assert again.sensor.analysed == 0 and again.sensor.reused == 2


def test_a_vision_campaign_with_missing_images_names_each_one(tmp_path):
    cfg = vision_config(delta_robot(), paper48()[[21]], paper9(), repeats=1)
    write_campaign(tmp_path, cfg, render_images=False)  # the spec and the truth, no images
    first = tmp_path / "images" / "p01" / "l01_r01_unloaded.png"
    first.parent.mkdir(parents=True)
    first.write_bytes(b"not pixels")
    calls = []
    done = run_and_export(tmp_path, progress=lambda *a: calls.append(a))
    assert done.sensor is None and done.vision.positions == 1
    missing = [f for f in done.failures if f.endswith("image not found (position 1)")]
    assert len(missing) == 17  # 9 load cases x (unloaded + loaded), but the first
    assert done.failures == done.vision.failures
    summary = json.loads((done.exports / "summary.json").read_text())
    assert summary["failures"] == done.failures
    assert calls and all(c[0] <= c[1] for c in calls)  # progress(done, total, measured)
