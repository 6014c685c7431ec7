"""The scripts of examples/ run, on small settings, and give what they say they give."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from helpers.shared_data import CALIB_DIR

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _example(name: str):
    """The module of examples/NAME.py (not a package: loaded from its file)."""
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_identify_from_csv_recovers_the_known_K(capsys):
    res = _example("identify_from_csv").main(["--demo"])
    # The demo's K (written in the example) with 0.2 um of noise: within 5 of its own sigmas.
    K_true = np.array([[60.0, 4.0, -2.0], [4.0, 45.0, 3.0], [-2.0, 3.0, 200.0]])
    assert np.all(np.abs(res.fit.K - K_true) <= 5 * res.fit.K_std)
    assert "principal stiffnesses" in capsys.readouterr().out


def test_urdf_arm_map_scales_with_the_joint_springs(capsys):
    """Joint springs only: K is linear in k1..k6, so doubling them all doubles every K."""
    ex = _example("urdf_arm_map")
    grid = "400:650:2,-150:150:2,400"
    m1 = ex.main(["--grid", grid])
    ks = ",".join(f"{2 * k:g}" for k in ex.arm6.K_THETA)
    m2 = ex.main(["--grid", grid, "--k", ks])
    assert m1.n_valid == len(m1) == 4
    np.testing.assert_allclose(m2.K, 2 * m1.K, rtol=1e-9)
    # Mirror-symmetric arm about the x-z plane: y and -y give the same principal stiffnesses.
    np.testing.assert_allclose(m1.eigenvalues[0], m1.eigenvalues[2], rtol=1e-9)
    assert "softest at" in capsys.readouterr().out


def test_calibrate_camera_on_the_real_photographs(capsys, tmp_path):
    """Bouguet's published fc, cc on these 20 photographs (../shared/data/calib_example/README.md:
    a right calibration lands within about 0.5 px of fc and 1.5 px of cc)."""
    res = _example("calibrate_camera").main([str(CALIB_DIR), "--out", str(tmp_path / "c.json")])
    cam = res.camera
    assert res.n_used >= 19
    assert abs(cam.fx - 657.4629) <= 0.6 and abs(cam.fy - 657.9467) <= 0.6  # px
    assert abs(cam.cx - 303.1366) <= 1.5 and abs(cam.cy - 242.5693) <= 1.5
    assert (tmp_path / "c.json").is_file()
    assert "fc = [" in capsys.readouterr().out


@pytest.mark.long  # 16 s: renders and measures a campaign
def test_simulated_campaign_measures_the_true_K(tmp_path, capsys):
    done, rows, truth = _example("simulated_campaign").main([str(tmp_path / "c"), "--select", "1"])
    (r,) = rows
    assert r.status == "ok" and r.position == 1
    Kt = np.asarray(truth.K[0])
    # The true camera, noise of the rendered images only: K within 5 % (Frobenius) of the truth.
    assert np.linalg.norm(r.K - Kt) / np.linalg.norm(Kt) < 0.05
    assert "|K - K_true|" in capsys.readouterr().out
