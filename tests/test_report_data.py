"""The report's data contract: checks at construction, derived values, JSON round trip, errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from helpers.random_matrices import random_spd

from stiffmap.errors import InputError
from stiffmap.report import load_report_data
from stiffmap.report.data import (
    SCHEMA,
    CalibrationData,
    CampaignInfo,
    Failure,
    LoadData,
    MeasuredStiffness,
    ModelMap,
    ModelStiffness,
    Parameter,
    ReportData,
    SensorMap,
    SensorResults,
    TruthStiffness,
)


def _random_vision(rng: np.random.Generator, n: int = 7, L: int = 4, R: int = 3) -> ReportData:
    """Random but consistent data touching every field, with NaN where allowed."""
    pos = rng.uniform(-200, 200, size=(n, 3))
    K = np.stack([random_spd(rng) for _ in range(n)])
    K_std = rng.uniform(0.001, 0.1, size=(n, 3, 3))
    K[2] = np.nan
    K_std[2] = np.nan
    flags = [()] * n
    flags[4] = ("asymmetric: |K-K^T|/|K| = 0.2 > 0.1", "det <= 0: det(K) = -1")
    measured = MeasuredStiffness.from_K(
        pos, K, K_std, messages=[""] * 2 + ["img3.png: not found"] + [""] * (n - 3), flags=flags
    )
    norms = rng.uniform(0.01, 3.0, size=(n, L, R))
    norms[1, 2, 0] = np.nan
    Km = np.stack([random_spd(rng) for _ in range(n)])
    mp = rng.uniform(-200, 200, size=(11, 3))
    cam = {
        "image_size": [640, 480],
        "fx": 800.0,
        "fy": 801.5,
        "cx": 320.0,
        "cy": 240.0,
        "dist": [0.1, -0.2, 0, 0, 0.01],
    }
    return ReportData(
        campaign=CampaignInfo("rand <b>", "vision", date="2026-01-01", notes="a & b"),
        measured=measured,
        loads=LoadData(tuple(f"load {k}" for k in range(L)), rng.normal(size=(L, 3)), norms),
        model=ModelStiffness.from_K(
            "m",
            [Parameter("k", 2.0, 0.1, "N*mm/rad"), Parameter("fixed", 1.0)],
            Km,
            map=ModelMap(mp, rng.normal(size=11), np.r_[rng.normal(size=10), np.nan]),
        ),  # fmt: skip
        truth=TruthStiffness(np.stack([random_spd(rng) for _ in range(n)])),
        calibration=CalibrationData(cam, rng.normal(0, 0.2, size=(20, 2))),
        sensor=SensorResults(
            points=rng.uniform(0, 500, size=(5, 2)),
            direction=("x", "y", "x", "y", "x"),
            error_um=np.array([100.0, 200.0, np.nan, 150.0, 120.0]),
            error_std_um=np.array([3.0, 4.0, np.nan, 5.0, 6.0]),
            model_error_um=rng.uniform(50, 300, size=5),
            middle_line=np.array([True, False, True, True, False]),
            parameters=(Parameter("kj", 525.0, 10.0, "N/mm"),),
            maps=(SensorMap("x", rng.uniform(0, 500, size=(6, 2)), np.r_[rng.uniform(1, 9, 5), np.nan]),),
        ),
        failures=(Failure("position 3", "img3.png: not found"),),
    )


def _assert_same(a, b, path="") -> None:
    """Deep equality of two records (arrays equal with NaN where NaN)."""
    if hasattr(a, "__dataclass_fields__"):
        assert type(a) is type(b), path
        for k in a.__dataclass_fields__:
            _assert_same(getattr(a, k), getattr(b, k), f"{path}.{k}")
    elif isinstance(a, np.ndarray):
        assert a.shape == b.shape and a.dtype == b.dtype, path
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), path
    elif isinstance(a, tuple):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and math.isnan(a):
        assert isinstance(b, float) and math.isnan(b), path
    else:
        assert a == b, path


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_json_round_trip_over_random_draws(seed: int, tmp_path) -> None:
    data = _random_vision(np.random.default_rng(seed))
    text = json.dumps(data.to_dict(), allow_nan=False)  # strict JSON: NaN became null
    back = ReportData.from_dict(json.loads(text))
    _assert_same(data, back)
    p = tmp_path / "data.json"
    p.write_text(text)
    _assert_same(data, load_report_data(p))


def test_indices_from_K_match_numpy(rng) -> None:
    n = 6
    K = np.stack([random_spd(rng) + 0.3 * rng.normal(size=(3, 3)) for _ in range(n)])
    m = MeasuredStiffness.from_K(rng.normal(size=(n, 3)), K)
    S = 0.5 * (K + np.swapaxes(K, 1, 2))
    np.testing.assert_allclose(m.det, np.linalg.det(K), rtol=1e-12, atol=0)
    np.testing.assert_allclose(m.eigenvalues, np.linalg.eigvalsh(S), rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.min_principal, np.linalg.eigvalsh(S)[:, 0], rtol=0, atol=1e-12)
    assert m.status == ("ok",) * n


def test_failed_positions_by_nan_get_status_and_no_indices(rng) -> None:
    K = np.stack([random_spd(rng) for _ in range(3)])
    K[1] = np.nan
    m = MeasuredStiffness.from_K(np.zeros((3, 3)), K)
    assert m.status == ("ok", "failed", "ok")
    assert m.messages[1] == "no stiffness"
    assert np.isnan(m.det[1]) and np.isnan(m.min_principal[1]) and np.isnan(m.eigenvalues[1]).all()
    np.testing.assert_array_equal(m.ok, [True, False, True])


def test_ok_position_with_nan_is_refused(rng) -> None:
    K = np.stack([random_spd(rng) for _ in range(2)])
    K[0, 1, 1] = np.nan
    with pytest.raises(ValueError, match=r"K\[0\]: position 0 has status 'ok' but K holds NaN"):
        MeasuredStiffness.from_K(np.zeros((2, 3)), K, status=["ok", "ok"])


def test_failed_position_needs_a_message(rng) -> None:
    K = np.full((1, 3, 3), np.nan)
    with pytest.raises(ValueError, match="failed; say why"):
        MeasuredStiffness.from_K(np.zeros((1, 3)), K, messages=[""])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"positions": np.zeros((2, 2))}, r"positions: expected shape \(n, 3\), got \(2, 2\)"),
        ({"K_std": np.zeros((3, 3, 3))}, r"K_std: expected shape \(n, 3, 3\) with n = 2, got \(3, 3, 3\)"),
        ({"status": ("ok", "maybe")}, "status: expected 'ok' or 'failed', got 'maybe'"),
        ({"det": np.array([1.0, np.inf])}, "det: infinite values"),
        ({"flags": (("a",),)}, "flags: expected 2 lists, got 1"),
    ],
)
def test_measured_checks_name_the_field(kwargs, match, rng) -> None:
    K = np.stack([random_spd(rng) for _ in range(2)])
    m = MeasuredStiffness.from_K(np.zeros((2, 3)), K)
    fields = {k: getattr(m, k) for k in m.__dataclass_fields__}
    fields.update(kwargs)
    with pytest.raises(ValueError, match=match):
        MeasuredStiffness(**fields)


def test_load_summary_matches_nan_statistics(rng) -> None:
    norms = rng.uniform(0.1, 2.0, size=(4, 3, 5))
    norms[0, 0, :3] = np.nan  # two repeats left
    norms[1, 2, 1:] = np.nan  # one repeat: no std
    norms[2, 1, :] = np.nan  # none
    ld = LoadData(("a", "b", "c"), np.eye(3), norms)
    mean, std, cnt = ld.summary()
    with np.errstate(all="ignore"), pytest.warns(RuntimeWarning):
        ref_mean = np.nanmean(norms, axis=2)
        ref_std = np.nanstd(norms, axis=2, ddof=1)
    ref_std[cnt < 2] = np.nan
    np.testing.assert_allclose(mean, ref_mean, rtol=1e-13, atol=0)
    np.testing.assert_allclose(std, ref_std, rtol=1e-12, atol=0)
    assert cnt[0, 0] == 2 and cnt[1, 2] == 1 and cnt[2, 1] == 0 and cnt[3, 0] == 5


def test_negative_norm_refused() -> None:
    with pytest.raises(ValueError, match="norms: a displacement norm is negative"):
        LoadData(("a",), np.ones((1, 3)), -np.ones((2, 1, 3)))


def test_truth_error_and_residuals(rng) -> None:
    n = 4
    Kt = np.stack([random_spd(rng) for _ in range(n)])
    E = 0.01 * rng.normal(size=(n, 3, 3))
    K = Kt + E
    K[3] = np.nan
    m = MeasuredStiffness.from_K(np.zeros((n, 3)), K)
    Km = np.stack([random_spd(rng) for _ in range(n)])
    d = ReportData(
        CampaignInfo("t", "vision"),
        measured=m,
        truth=TruthStiffness(Kt),
        model=ModelStiffness.from_K("m", [], Km),
    )
    err = d.truth_error
    ref = np.linalg.norm(E, axis=(1, 2)) / np.linalg.norm(Kt, axis=(1, 2))
    np.testing.assert_allclose(err[:3], ref[:3], rtol=1e-12, atol=0)
    assert np.isnan(err[3])
    r = d.residuals
    np.testing.assert_allclose(
        r.det[:3], np.linalg.det(K[:3]) - np.linalg.det(Km[:3]), rtol=1e-10, atol=1e-12
    )
    np.testing.assert_allclose(r.K[:3], K[:3] - Km[:3], rtol=0, atol=1e-15)
    assert np.isnan(r.det[3]) and np.isnan(r.K[3]).all()


def test_parts_must_agree_on_the_number_of_positions(rng) -> None:
    m = MeasuredStiffness.from_K(np.zeros((3, 3)), np.stack([random_spd(rng) for _ in range(3)]))
    with pytest.raises(ValueError, match="truth.K: 2 positions, but measured has 3"):
        ReportData(CampaignInfo("t", "vision"), measured=m, truth=TruthStiffness(np.stack([np.eye(3)] * 2)))
    with pytest.raises(ValueError, match="a vision campaign needs the measured stiffness"):
        ReportData(CampaignInfo("t", "vision"))
    with pytest.raises(ValueError, match="a sensor campaign needs the sensor results"):
        ReportData(CampaignInfo("t", "sensor"), measured=m)
    with pytest.raises(ValueError, match="kind: expected one of vision, sensor, got 'optical'"):
        CampaignInfo("t", "optical")


def test_calibration_checks_the_camera_dict() -> None:
    with pytest.raises(ValueError, match="missing keys 'fx', 'fy'"):
        CalibrationData({"image_size": [10, 10], "cx": 1.0, "cy": 1.0, "dist": [0, 0, 0, 0]})
    with pytest.raises(ValueError, match=r"corner_residuals_px: expected shape \(N, 2\)"):
        CalibrationData(
            {"image_size": [10, 10], "fx": 5.0, "fy": 5.0, "cx": 1.0, "cy": 1.0, "dist": [0, 0, 0, 0]},
            np.zeros((4, 3)),
        )


def test_sensor_checks() -> None:
    base = dict(points=np.zeros((2, 2)), direction=("x", "y"), error_um=[1.0, 2.0], error_std_um=[0.1, 0.1])
    s = SensorResults(**base)
    assert s.labels == ("1", "2") and s.directions == ("x", "y") and s.reference_load_n == 490.5
    with pytest.raises(ValueError, match="direction: expected 2 entries, got 1"):
        SensorResults(**{**base, "direction": ("x",)})
    with pytest.raises(ValueError, match="middle_line: expected 2 booleans"):
        SensorResults(**base, middle_line=np.array([1, 0]))
    with pytest.raises(ValueError, match="reference_load_n: expected a positive number"):
        SensorResults(**base, reference_load_n=0.0)


def _dump(rng) -> dict:
    return _random_vision(rng).to_dict()


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda d: d.pop("schema"), "key 'schema': expected 'stiffmap.report/1', got None"),
        (lambda d: d["measured"].pop("K"), "key 'measured.K' is missing"),
        (
            lambda d: d["measured"].__setitem__("K", [[1, 2, 3]]),
            "key measured.K: expected shape (n, 3, 3), got (1, 3)",
        ),
        (lambda d: d["loads"].__setitem__("colour", "red"), "key 'loads.colour': unknown key"),
        (
            lambda d: d["model"]["parameters"][0].__setitem__("value", "big"),
            "key model.parameters[0].value: expected a number",
        ),
        (lambda d: d["sensor"].__setitem__("maps", {}), "key 'sensor.maps': expected a list, got dict"),
        (
            lambda d: d["campaign"].__setitem__("kind", "x-ray"),
            "key campaign.kind: expected one of vision, sensor",
        ),
        (lambda d: d.__setitem__("truth", 5), "key 'truth': expected an object, got int"),
    ],
)
def test_from_dict_errors_name_the_key(edit, needle, rng) -> None:
    d = _dump(rng)
    edit(d)
    with pytest.raises(InputError) as e:
        ReportData.from_dict(d, source="run/data.json")
    assert str(e.value).startswith("run/data.json: ")
    assert needle in str(e.value)


def test_load_report_data_errors(tmp_path) -> None:
    with pytest.raises(InputError, match="nope.json: file not found"):
        load_report_data(tmp_path / "nope.json")
    p = tmp_path / "bad.json"
    p.write_text('{"schema": "stiffmap.report/1", ')
    with pytest.raises(InputError, match=r"bad.json: not valid JSON: .* at line 1"):
        load_report_data(p)
    p.write_text(json.dumps({"schema": SCHEMA, "campaign": {"name": "x"}}))
    with pytest.raises(InputError, match="key 'campaign.kind' is missing"):
        load_report_data(p)


def test_arrays_are_read_only(rng) -> None:
    d = _random_vision(rng)
    with pytest.raises(ValueError, match="read-only"):
        d.measured.K[0, 0, 0] = 1.0


def test_importing_the_report_package_loads_no_plotting_library() -> None:
    code = (
        "import sys, stiffmap.report, stiffmap.report.data; "
        "heavy = sorted(m for m in ('plotly', 'matplotlib', 'scipy') if m in sys.modules); "
        "print(','.join(heavy))"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == ""
