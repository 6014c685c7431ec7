"""The camera calibration's common error through a campaign: displacements and K.

A camera error is common to every image of a campaign: the campaign carries each
displacement's sensitivity to the camera's parameters and K's share of the calibration's
covariance (``stiffmap.campaign.derive``). Checked here against finite differences of the
whole chain: the same rendered images measured again with a camera moved along one
direction of its parameters, derived again, and differenced.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stiffmap.camera import CameraModel, save_camera
from stiffmap.campaign.demo import demo_config
from stiffmap.campaign.derive import derive_position
from stiffmap.campaign.export import read_tables
from stiffmap.campaign.measure import MeasureContext, measure_position
from stiffmap.campaign.positions import plan
from stiffmap.campaign.records import DisplacementRecord, StiffnessRecord
from stiffmap.campaign.runner import run_vision_campaign
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import DB_NAME, SCHEMA_VERSION, Store, record_of
from stiffmap.report.campaign import write_campaign_report

pytestmark = pytest.mark.slow


def _calibration_cov(cam: CameraModel) -> np.ndarray:
    """A plausible calibration covariance: std fx, fy 0.5 px (correlated 0.9), cx, cy 0.4 px,
    k1 1e-3, k2 3e-3, p1, p2 5e-5, k3 1e-2 (the size of a 20-view calibration's)."""
    s = np.array([0.5, 0.5, 0.4, 0.4, 1e-3, 3e-3, 5e-5, 5e-5, 1e-2])[: len(cam.params)]
    R = np.eye(s.size)
    R[0, 1] = R[1, 0] = 0.9
    return R * np.outer(s, s)


@pytest.fixture(scope="module")
def one_position(tmp_path_factory):
    """One position of the demo set-up, nine loads, one repeat, the true camera with a covariance."""
    cfg = demo_config(quick=True, repeats=1)
    cfg = dataclasses.replace(cfg, positions=cfg.positions[[2]])
    if "calibration_views" in {f.name for f in dataclasses.fields(cfg)}:
        cfg = dataclasses.replace(cfg, calibration_views=0)
    out = tmp_path_factory.mktemp("calcov") / "c"
    write_campaign(out, cfg, workers=1)
    cam = CameraModel.from_dict(dict(cfg.scene.camera.to_dict()))
    cam = dataclasses.replace(cam, cov=_calibration_cov(cam))
    save_camera(cam, out / "camera.json")
    return out, cam


def _derive(root, camera: CameraModel, calibration_cov):
    spec = load_spec(root)
    (task,) = plan(spec, root)
    ctx = dataclasses.replace(MeasureContext.from_spec(spec, root, camera), refine="corners")
    rows = {r.image: r for r in measure_position(ctx, task)}
    assert all(r.ok for r in rows.values()), [r.error for r in rows.values()]
    loads = spec.loads.resolve(spec.g)
    return derive_position(task, rows, loads, spec, "compliance", "", "", calibration_cov=calibration_cov)


def test_calibration_share_of_displacements_and_K_matches_finite_differences(one_position):
    """Along one direction u of the camera's parameters (Sigma_c = u u^T) the stored shares are
    v v^T with v the change of the displacement and of K per unit of u: checked by measuring
    the images again with the camera at c +- h u."""
    root, cam = one_position
    w, V = np.linalg.eigh(cam.cov)
    u = V[:, -1] * np.sqrt(w[-1]) + V[:, -2] * np.sqrt(w[-2])  # a 1-sigma-sized direction
    res = _derive(root, cam, np.outer(u, u))
    h = 20.0  # 20 sigma: the chain's change well above the pose solver's tolerance, still linear
    plus = _derive(root, cam.with_params(cam.params + h * u), None)
    minus = _derive(root, cam.with_params(cam.params - h * u), None)

    for row, rp, rm in zip(res.displacements, plus.displacements, minus.displacements, strict=True):
        v = (record_of(DisplacementRecord, rp).d - record_of(DisplacementRecord, rm).d) / (2 * h)
        pred = record_of(DisplacementRecord, row).cov_calibration
        # A displacement's sensitivity is the difference of two poses' ~1000 times larger ones
        # (0.15 mm per sigma each, which agree with re-measurement to ~1e-5 of themselves): it
        # is known to 3 % or 0.5 nm per sigma, far below any displacement's noise (um).
        np.testing.assert_allclose(np.sqrt(np.diag(pred))[:3], np.abs(v[:3]), rtol=0.03, atol=5e-7)
    v = (
        record_of(StiffnessRecord, plus.stiffness).K - record_of(StiffnessRecord, minus.stiffness).K
    ).ravel() / (2 * h)
    pred = record_of(StiffnessRecord, res.stiffness).K_cov_calibration
    assert np.linalg.norm(pred - np.outer(v, v)) < 0.05 * np.linalg.norm(np.outer(v, v))
    # The total covariance holds the share on top of the noise's.
    noise = _derive(root, cam, None)
    np.testing.assert_allclose(
        record_of(StiffnessRecord, res.stiffness).K_cov,
        record_of(StiffnessRecord, noise.stiffness).K_cov + pred,
        rtol=1e-9,
        atol=1e-15,
    )


def test_run_stores_and_exports_the_calibration_share(one_position, tmp_path):
    root, cam = one_position
    import shutil

    work = tmp_path / "c"
    shutil.copytree(root, work)
    summary = run_vision_campaign(work, workers=1)
    assert not summary.failures, summary.failures
    with Store(work / DB_NAME, read_only=True) as store:
        (st,) = store.stiffness_rows()
        tables = read_tables(store)
        for r in store.measurement_rows():
            assert r.mobile_cal_jac.shape == (6, cam.params.size)
    Kc = st.K_cov_calibration
    assert Kc.shape == (9, 9) and np.all(np.diag(Kc) > 0)
    shares = [tables["stiffness"][0][f"cal_share_k{k}{k}"] for k in (1, 2, 3)]
    assert all(0 < s < 1 for s in shares), shares
    for d in tables["displacements"]:
        assert all(0 < d[f"cal_share_d{c}"] < 1 for c in "xyz"), d
    # The report says it too, beside the camera's table.
    page = write_campaign_report(work, summary.failures).read_text(encoding="utf-8")
    assert "share of the variance of k11, k22, k33: median" in page


def test_a_schema_1_database_gets_the_new_columns(tmp_path):
    """An older results database is brought up to date in place, its rows kept."""
    import sqlite3

    db = tmp_path / DB_NAME
    with Store(db):
        pass
    conn = sqlite3.connect(db)
    conn.execute("ALTER TABLE stiffness DROP COLUMN K_cov_calibration")
    conn.execute("ALTER TABLE measurements DROP COLUMN mobile_cal_jac")
    conn.execute("ALTER TABLE measurements DROP COLUMN per_camera")  # schema 3
    conn.execute(
        "INSERT INTO stiffness (position, x, y, z, K, status, inputs_hash, params_hash, version) "
        "VALUES (1, 0, 0, 0, '[[1,0,0],[0,1,0],[0,0,1]]', 'ok', 'h', 'p', 'v')"
    )
    conn.execute("UPDATE meta SET value = '1' WHERE key = 'schema_version'")
    conn.commit()
    conn.close()
    with Store(db) as store:
        (row,) = store.stiffness_rows()
        assert row.K_cov_calibration is None and row.status == "ok"
        np.testing.assert_array_equal(row.K, np.eye(3))
        assert store.measurement_rows() == []
    conn = sqlite3.connect(db)
    cols = {r[1] for r in conn.execute("PRAGMA table_info(measurements)")}
    assert {"mobile_cal_jac", "per_camera"} <= cols
    assert conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()[0] == str(
        SCHEMA_VERSION
    )
    conn.close()
