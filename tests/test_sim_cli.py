"""``stiffmap simulate`` as a user runs it: files, determinism, JSON, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.board_scenes import scaled_camera
from helpers.cli_process import assert_one_line_error, run_here

from stiffmap.camera import load_camera, reference_camera, save_camera
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.truth import load_truth
from stiffmap.models.delta import DeltaRobot
from stiffmap.models.presets import paper48, prr3_points22
from stiffmap.models.prr3 import PRR3


def test_truth_only_json_summary(tmp_path):
    out = tmp_path / "sim"
    p = run_here("simulate", out, "--select", "1,48", "--repeats", "2", "--truth-only", "--json")
    assert p.returncode == 0, p.stderr
    info = json.loads(p.stdout)
    assert info["positions"] == 2 and info["load_cases"] == 9 and info["repeats"] == 2
    assert info["images"] == 0 and info["robot"] == "delta" and info["field"] == "3x3"
    truth = load_truth(out)
    np.testing.assert_allclose(truth.positions, paper48()[[0, 47]])
    np.testing.assert_allclose(truth.K, DeltaRobot().stiffness(paper48()[[0, 47]]), rtol=1e-12)  # N/mm
    assert len(truth.images()) == 2 * 9 * 2 * 2
    lo, hi = info["principal_stiffness_range"]
    w = np.linalg.eigvalsh(truth.K)
    assert (lo, hi) == (w.min(), w.max())
    assert truth.data["generator"]["command"].startswith("stiffmap simulate")
    # No images, nothing to calibrate from: camera.json is the true camera, and the summary says so.
    assert info["calibration"]["camera_json"] == "true camera" and "truth only" in info["calibration"]["note"]
    assert truth.calibrated_camera is None and load_camera(out / "camera.json") == truth.camera
    table = run_here("simulate", tmp_path / "t", "--select", "1", "--truth-only", columns=80)
    assert table.returncode == 0 and "the true camera: truth only" in table.stdout


def test_images_are_written_and_reproducible(tmp_path):
    cam = tmp_path / "small_camera.json"
    save_camera(scaled_camera(reference_camera(), 0.25), cam)
    loads = tmp_path / "loads.csv"
    loads.write_text("fx,fy,fz,label\n0,0,-4.905,0.5 kg down\n-2,0,0,2 N -x\n0,3,0,3 N +y\n")
    args = ["--camera", cam, "--positions", "100,-50,-250", "--loads", loads, "--repeats", "1"]
    args += ["--seed", "11", "--clutter", "--colour", "--calibration-views", "4"]
    a = run_here("simulate", tmp_path / "a", *args, "--workers", "1")
    b = run_here("simulate", tmp_path / "b", *args, "--workers", "2")
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    assert "6 png + 4 calibration views" in a.stdout and "rendering" in a.stderr
    assert "calibrated from 4 of 4 views, RMS" in a.stdout and "calibration vs true camera" in a.stdout
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*.png"))
    assert len(files) == 6 + 4
    for rel in files:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()
    # The same seed, the same calibration: camera.json is byte-identical too.
    assert (tmp_path / "a" / "camera.json").read_bytes() == (tmp_path / "b" / "camera.json").read_bytes()
    assert load_camera(tmp_path / "a" / "camera.json") != load_camera(cam)
    spec = load_spec(tmp_path / "a")
    assert [ld.label for ld in spec.loads.resolve(spec.g)] == ["0.5 kg down", "2 N -x", "3 N +y"]
    truth_a = (tmp_path / "a" / "truth.json").read_text()
    truth_b = (tmp_path / "b" / "truth.json").read_text()
    # Identical but for the recorded command line (the directory and --workers differ).
    ja, jb = json.loads(truth_a), json.loads(truth_b)
    ja["generator"].pop("command")
    jb["generator"].pop("command")
    assert ja == jb
    # --force overwrites a previous simulation.
    c = run_here("simulate", tmp_path / "a", *args, "--truth-only", "--force", "--json")
    assert c.returncode == 0, c.stderr
    assert not (tmp_path / "a" / "images").exists() and not (tmp_path / "a" / "calibration").exists()
    # --true-camera: no calibration views, camera.json is the true camera exactly.
    d = run_here("simulate", tmp_path / "d", *args[:-2], "--true-camera", "--json")
    assert d.returncode == 0, d.stderr
    info = json.loads(d.stdout)
    assert info["calibration"]["camera_json"] == "true camera" and info["calibration"]["views"] == 0
    assert (tmp_path / "d" / "camera.json").read_text() == cam.read_text()
    assert not (tmp_path / "d" / "calibration").exists()
    assert sorted(p.name for p in (tmp_path / "d" / "images").rglob("*.png")) == sorted(
        p.name for p in (tmp_path / "b" / "images").rglob("*.png")
    )  # the campaign's own images do not depend on the calibration
    for rel in files[4:]:
        assert (tmp_path / "d" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()


def test_six_by_six_option(tmp_path):
    p = run_here(
        "simulate",
        tmp_path / "s",
        "--select",
        "22",
        "--repeats",
        "1",
        "--truth-only",
        "--rot-stiffness-nmm-per-rad",
        "5e4",
        "--load-point-mm",
        "0,0,-25",
        "--param",
        "k_theta=3e5",
        "--json",
    )
    assert p.returncode == 0, p.stderr
    t = load_truth(tmp_path / "s")
    assert t.data["robot"]["field"] == "6x6" and t.data["robot"]["params"]["k_theta"] == 3e5
    K6 = np.asarray(t.data["positions"][0]["K_tcp"])
    np.testing.assert_allclose(K6[:3, :3], DeltaRobot(k_theta=3e5).stiffness(paper48()[21]), rtol=1e-12)
    # No coupling: the tool point moves as with the 3x3 field, and the platform turns by
    # |r x F| / k_rot about x under load 1 (0.5 kg along +y hung 25 mm below the tool point).
    np.testing.assert_allclose(t.K[0], K6[:3, :3], rtol=1e-12)
    loaded = next(im for im in t.images() if im["load"] == 1 and im["state"] == "loaded")
    R = np.asarray(loaded["tcp2base"])[:3, :3]
    angle = np.arctan2(R[2, 1], R[1, 1])  # about x
    assert angle == pytest.approx(25.0 * 4.905 / 5e4, abs=1e-4)  # rad; repeatability 2e-5 rad


def test_user_errors_are_one_line(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x.png").write_bytes(b"raw")
    assert_one_line_error(run_here("simulate", tmp_path / "full", "--truth-only"), "not empty", "--force")
    assert_one_line_error(
        run_here("simulate", tmp_path / "full", "--truth-only", "--force"), "nothing was deleted"
    )
    assert (tmp_path / "full" / "x.png").read_bytes() == b"raw"
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--robot", "3prr", "--positions", "paper48"), "delta model"
    )
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--robot", "3prr", "--directions", "z"), "x and/or y"
    )
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--positions", "1,2"), "--positions", "x,y,z")
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--select", "0,49"), "between 1 and 48")
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--positions", "0,0,-310;0,0,-900", "--truth-only"),
        "position 2 (0, 0, -900) mm",
        "no stiffness",
    )
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--param", "k_nope=1"), "k_nope")
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--select", "1,1"), "more than once")
    # Options of the other kind of simulation are refused, not silently ignored.
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--robot", "3prr", "--colour", "--camera", "c.json"),
        "--camera, --colour",
        "not used",
    )
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--trace-format", "mat"), "--trace-format")
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--robot", "3prr", "--true-camera"),
        "--true-camera",
        "not used",
    )
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--calibration-views", "2"),
        "--calibration-views 2",
        "at least 3",
    )
    assert_one_line_error(
        run_here("simulate", tmp_path / "n", "--true-camera", "--calibration-views", "5"), "choose one"
    )
    # A calibration that fails (8 px of blur: the board is found in too few views) stops the
    # simulation with its reason, before any campaign image is rendered.
    cam = tmp_path / "small_camera.json"
    save_camera(scaled_camera(reference_camera(), 0.25), cam)
    blurred = ["--camera", cam, "--select", "22", "--repeats", "1", "--blur-px", "8"]
    blurred += ["--calibration-views", "3", "--json"]  # --json: no progress bar on stderr
    assert_one_line_error(
        run_here("simulate", tmp_path / "blur", *blurred),
        str(tmp_path / "blur" / "calibration"),
        "could not be calibrated from the 3 rendered calibration views",
        "at least 3 views with the board found",
    )
    assert not (tmp_path / "blur" / "images").exists()
    flat = tmp_path / "flat.csv"
    flat.write_text("fx,fy,fz\n1,0,0\n2,0,0\n")
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--loads", flat), "1 independent direction")
    bad = tmp_path / "loads.csv"
    bad.write_text("fx,fy\n1,2\n")
    assert_one_line_error(run_here("simulate", tmp_path / "n", "--loads", bad), str(bad), "'fz'")
    assert not (tmp_path / "n").exists()


def test_3prr_sensor_campaign_round_trip(tmp_path):
    # The 3PRR is measured by an LDV: 'simulate --robot 3prr' writes a sensor campaign whose
    # recordings 'stiffmap run' analyses; the static errors come back to the truth.
    out = tmp_path / "s"
    p = run_here(
        "simulate", out, "--robot", "3prr", "--select", "2,8,19", "--repeats", "1", "--seed", "5", "--json"
    )
    assert p.returncode == 0, p.stderr
    info = json.loads(p.stdout)
    assert info["kind"] == "sensor" and info["recordings"] == 6
    spec = load_spec(out)
    assert spec.kind == "sensor" and spec.robot.model == "3prr"
    assert [r.direction for r in spec.sensor.recordings] == ["x", "y"] * 3
    assert [r.sign for r in spec.sensor.recordings] == [-1, 1] * 3  # x through a mirror
    truth = load_truth(out)
    pts = prr3_points22()[[1, 7, 18]]
    np.testing.assert_allclose(truth.positions, pts)
    np.testing.assert_allclose(truth.K, PRR3().stiffness(pts), rtol=1e-12)  # N/mm
    r = run_here("run", out, "--json")
    assert r.returncode == 0, r.stderr
    res = {x["file"]: x for x in json.loads(r.stdout)["sensor_results"]}
    for rec in truth.data["recordings"]:
        got = res[rec["file"]]["static_error_um"]
        assert abs(got - rec["static_error_um"]) <= 1.0 + 0.01 * abs(rec["static_error_um"])  # um
    # Static errors along the load at 50 kgf, from K: u . K^-1 (490.5 N u).
    e0 = truth.data["positions"][0]
    assert e0["static_error_y_mm"] == pytest.approx(np.linalg.solve(truth.K[0], [0.0, 490.5])[1], rel=1e-12)
