"""``stiffmap simulate`` as a user runs it: files, determinism, JSON, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _cli import assert_one_line_error, stiffmap
from _sim_helpers import scaled_camera

from stiffmap.camera import reference_camera, save_camera
from stiffmap.campaign.spec import load_spec
from stiffmap.models.delta import DeltaRobot
from stiffmap.models.presets import paper48
from stiffmap.sim.writer import load_truth


def test_truth_only_json_summary(tmp_path):
    out = tmp_path / "sim"
    p = stiffmap("simulate", out, "--select", "1,48", "--repeats", "2", "--truth-only", "--json")
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


def test_images_are_written_and_reproducible(tmp_path):
    cam = tmp_path / "small_camera.json"
    save_camera(scaled_camera(reference_camera(), 0.25), cam)
    loads = tmp_path / "loads.csv"
    loads.write_text("fx,fy,fz,label\n0,0,-4.905,0.5 kg down\n-2,0,0,2 N -x\n0,3,0,3 N +y\n")
    args = ["--camera", cam, "--positions", "100,-50,-250", "--loads", loads, "--repeats", "1"]
    args += ["--seed", "11", "--clutter", "--colour"]
    a = stiffmap("simulate", tmp_path / "a", *args, "--workers", "1")
    b = stiffmap("simulate", tmp_path / "b", *args, "--workers", "2")
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    assert "6 png" in a.stdout and "rendering" in a.stderr
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*.png"))
    assert len(files) == 6
    for rel in files:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()
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
    c = stiffmap("simulate", tmp_path / "a", *args, "--truth-only", "--force", "--json")
    assert c.returncode == 0, c.stderr
    assert not (tmp_path / "a" / "images").exists()


def test_six_by_six_option(tmp_path):
    p = stiffmap(
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
    assert_one_line_error(stiffmap("simulate", tmp_path / "full", "--truth-only"), "not empty", "--force")
    assert_one_line_error(
        stiffmap("simulate", tmp_path / "full", "--truth-only", "--force"), "nothing was deleted"
    )
    assert (tmp_path / "full" / "x.png").read_bytes() == b"raw"
    assert_one_line_error(stiffmap("simulate", tmp_path / "n", "--robot", "3prr"), "not yet supported")
    assert_one_line_error(stiffmap("simulate", tmp_path / "n", "--positions", "1,2"), "--positions", "x,y,z")
    assert_one_line_error(stiffmap("simulate", tmp_path / "n", "--select", "0,49"), "between 1 and 48")
    assert_one_line_error(
        stiffmap("simulate", tmp_path / "n", "--positions", "0,0,-310;0,0,-900", "--truth-only"),
        "position 2 (0, 0, -900) mm",
        "no stiffness",
    )
    assert_one_line_error(stiffmap("simulate", tmp_path / "n", "--param", "k_nope=1"), "k_nope")
    bad = tmp_path / "loads.csv"
    bad.write_text("fx,fy\n1,2\n")
    assert_one_line_error(stiffmap("simulate", tmp_path / "n", "--loads", bad), str(bad), "'fz'")
    assert not (tmp_path / "n").exists()
