"""``stiffmap sensor`` and the campaign entry points (several recordings, bad ones among them)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from helpers.cli_process import run_here
from helpers.sensor_traces import FAST_DAQ_CHAIN, FAST_LOAD_STEPS, quick_trace

from stiffmap.errors import InputError
from stiffmap.sensors import (
    MeasurementEntry,
    SensorConfig,
    read_measurement_index,
    static_errors_from_files,
    write_recording,
)
from stiffmap.sim.traces import LoadSteps, simulate_point_traces


def _output(p) -> str:
    """What the command printed, stdout then stderr (the messages)."""
    return p.stdout + p.stderr


@pytest.fixture
def three_files(tmp_path):
    """A good CSV, a saturating TDMS (5.5 mm > 5.12 mm range), a good MAT with a mirror."""
    good = quick_trace(0.8, seed=21)
    sat = quick_trace(5.5, seed=22)
    mir = quick_trace(0.3, seed=23, axis_sign=-1)
    paths = [
        write_recording(good.recording, tmp_path / "good.csv"),
        write_recording(sat.recording, tmp_path / "sat.tdms"),
        write_recording(mir.recording, tmp_path / "mirror.mat"),
    ]
    return paths, (good, sat, mir)


def test_json_reports_each_recording_and_the_bad_one_with_its_span(three_files):
    paths, (good, sat, _) = three_files
    res = run_here("sensor", *map(str, paths), "--json")
    assert res.returncode == 1, _output(res)  # some failed, others analysed
    objs = json.loads(res.stdout)
    assert [o["file"] for o in objs] == [str(p) for p in paths]
    g = objs[0]
    for key in ("steps", "stiffness_n_per_mm", "stiffness_std_n_per_mm", "static_error_um", "flags"):
        assert key in g
    assert set(g["steps"][0]) >= {"load_n", "displacement_um", "std_um", "n"}
    assert len(g["steps"]) == 7
    assert abs(g["static_error_um"] - 800.0) <= 1 + 8.0
    assert g["stiffness_n_per_mm"] == pytest.approx(490.5 / 0.8, rel=0.011)
    bad = objs[1]
    assert set(bad) == {"file", "error"}
    assert bad["error"].startswith(f"{paths[1]}: saturated samples: saturated from ")
    t0 = float(re.search(r"saturated from (\S+) s", bad["error"]).group(1))
    v = sat.recording.displacement_v
    assert t0 == pytest.approx(sat.recording.time_s[np.flatnonzero(np.abs(v) >= 7.99)[0]], abs=2e-3)
    # The mirrored one without --axis-sign: analysed, but flagged.
    assert any("sensor axis sign (-1 behind a mirror)" in f for f in objs[2]["flags"])


def test_text_output_exit_codes_and_options(three_files, tmp_path):
    paths, _ = three_files
    res = run_here("sensor", str(paths[2]), "--axis-sign", "-1")
    assert res.returncode == 0, _output(res)
    assert "static error at 490.5 N" in res.stdout and "flags" in res.stdout
    m = re.search(r"static error at 490\.5 N\s+(\S+) ±", res.stdout)
    assert abs(float(m.group(1)) - 300.0) <= 1 + 3.0
    # Nothing could be done: exit 2, one line on stderr, no traceback.
    res = run_here("sensor", str(paths[1]), str(tmp_path / "missing.csv"))
    assert res.returncode == 2
    assert "Traceback" not in _output(res)
    assert "missing.csv: file not found" in _output(res)
    # A bad option value is one line and exit 2.
    res = run_here("sensor", str(paths[0]), "--steps-kgf", "50,abc")
    assert res.returncode == 2 and "--steps-kgf: 'abc' is not a number" in _output(res)
    res = run_here("sensor", str(paths[0]), "--channel-map", "volts=x")
    assert res.returncode == 2 and "unknown key 'volts'" in _output(res)
    res = run_here("sensor")
    assert res.returncode == 2 and "give one or more recordings" in _output(res)


def test_table_of_steps_custom_columns_and_step_times(tmp_path):
    tr = quick_trace(0.6, seed=31, protocol=LoadSteps(plateau_s=2.0, transition_s=0.8, load_channel=False))
    t, v = tr.recording.time_s, tr.recording.displacement_v
    p = tmp_path / "ldv.csv"
    p.write_text("t,ch0\n" + "".join(f"{a:.17g},{b:.17g}\n" for a, b in zip(t, v, strict=True)))
    args = ["sensor", str(p), "--channel-map", "displacement=ch0,time=t,load=none", "--json"]
    res = run_here(*args, "--steps-kgf", "0,50,40,30,20,10,0")
    assert res.returncode == 0, _output(res)
    (o,) = json.loads(res.stdout)
    assert [s["load_n"] for s in o["steps"]] == pytest.approx(
        [0, 490.5, 392.4, 294.3, 196.2, 98.1, 0], abs=1e-9
    )
    assert abs(o["static_error_um"] - 600.0) <= 1 + 6.0
    # Fewer plateaus than the table: the message names the file and the spans.
    res = run_here(*args, "--steps-kgf", "0,50,45,40,30,20,10,0")
    assert res.returncode == 2
    (o,) = json.loads(res.stdout)
    assert o["error"].startswith(f"{p}: found 7 plateau(s) but the table of steps has 8")
    # Plateaus by hand.
    spans = ",".join(f"{a + 0.3:.3f}-{b - 0.3:.3f}" for a, b in tr.truth.plateaus_s)
    res = run_here(*args, "--steps-n", "0,490.5,392.4,294.3,196.2,98.1,0", "--step-times", spans)
    assert res.returncode == 0, _output(res)
    (o2,) = json.loads(res.stdout)
    assert abs(o2["static_error_um"] - 600.0) <= 1 + 6.0


def test_load_channel_named_in_newtons_or_volts_is_found_and_scaled(tmp_path):
    """force_n / load_v columns are found without --channel-map; a load-cell scale means volts."""
    tr = quick_trace(0.6, seed=33)
    t, v, kgf = tr.recording.time_s, tr.recording.displacement_v, tr.recording.load
    rows = zip(t, v, kgf * 9.81, kgf * 9.81 / 50.0, strict=True)  # N, and a 50 N/V load cell
    body = "".join(f"{a:.17g},{b:.17g},{c:.17g},{d:.17g}\n" for a, b, c, d in rows)
    (tmp_path / "n.csv").write_text(
        "time_s,displacement_v,force_n\n"
        + "".join(",".join(r.split(",")[:3]) + "\n" for r in body.splitlines())
    )
    (tmp_path / "v.csv").write_text(
        "time_s,displacement_v,load_v\n"
        + "".join(",".join(r.split(",")[:2] + r.split(",")[3:]) + "\n" for r in body.splitlines())
    )
    ref = run_here("sensor", str(write_recording(tr.recording, tmp_path / "kgf.csv")), "--json")
    n = run_here("sensor", str(tmp_path / "n.csv"), "--json")
    volts = run_here("sensor", str(tmp_path / "v.csv"), "--load-n-per-v", "50", "--json")
    assert ref.returncode == n.returncode == volts.returncode == 0, (_output(n), _output(volts))
    e = [json.loads(r.stdout)[0]["static_error_um"] for r in (ref, n, volts)]
    assert e[1] == pytest.approx(e[0], rel=1e-9) and e[2] == pytest.approx(e[0], rel=1e-9)
    bad = run_here("sensor", str(tmp_path / "v.csv"), "--load-n-per-v", "50", "--load-unit", "kgf")
    assert bad.returncode == 2 and "--load-n-per-v" in bad.stderr
    bad = run_here("sensor", str(tmp_path / "v.csv"), "--window-s", "-1")
    assert bad.returncode == 2 and "--window-s must be" in bad.stderr


def test_static_errors_per_point_for_maps_and_fits(tmp_path):
    """simulate_point_traces -> index.csv -> per-point static errors within 1 um + 1 % of the truth."""
    pts = [[0.0, 380.0], [0.0, 420.0], [0.0, 460.0], [0.0, 500.0]]
    dirs = [[1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.0, 1.0]]
    signs = [-1, 1, -1, 1]  # horizontal through a mirror, as in the milling study

    def compliance(p, u):  # mm/N along u; softer higher up and horizontally
        return 1e-3 * (1.0 + p[1] / 400.0) * (1.5 if u[0] else 1.0)

    truths = simulate_point_traces(
        tmp_path,
        pts,
        dirs,
        compliance,
        fmt="mat",
        axis_signs=signs,
        chain=FAST_DAQ_CHAIN,
        protocol=FAST_LOAD_STEPS,
    )
    entries = read_measurement_index(tmp_path / "index.csv")
    assert [e.axis_sign for e in entries] == signs
    entries.append(MeasurementEntry([0.0, 540.0], "y", str(tmp_path / "lost.mat")))
    ses = static_errors_from_files(entries)
    assert ses.valid.tolist() == [True] * 4 + [False]
    assert "lost.mat: file not found" in ses.reasons[4]
    assert np.isnan(ses.static_error_mm[4]) and not np.isnan(ses.static_error_mm[:4]).any()
    for i, tr in enumerate(truths):
        assert 1e3 * abs(ses.static_error_mm[i] - tr.static_error_mm) <= 1 + 0.01 * 1e3 * tr.static_error_mm
    obs = ses.observations()
    assert obs["points"].shape == (4, 2) and obs["value_mm"].shape == (4,)
    np.testing.assert_allclose(obs["force_n"], 490.5 * np.array(dirs), rtol=0, atol=1e-12)
    res = run_here("sensor", "--index", str(tmp_path / "index.csv"), "--json")
    assert res.returncode == 0, _output(res)
    rows = json.loads(res.stdout)
    assert [r["file"].endswith(f"trace_{i:03d}.mat") for i, r in enumerate(rows)] == [True] * 4
    assert rows[0]["static_error_um"] == pytest.approx(1e3 * ses.static_error_mm[0], rel=1e-12)
    # The index's axis_sign overrides the configuration's (one shared config for the campaign).
    ses2 = static_errors_from_files(entries[:1], config=SensorConfig(axis_sign=1))
    assert ses2.static_error_mm[0] == pytest.approx(ses.static_error_mm[0], rel=1e-12)


def test_index_with_direction_names(tmp_path):
    (tmp_path / "idx.csv").write_text("x,y,z,direction,file\n0,0,-300,-z,a.csv\n10,0,-300,x,b.csv\n")
    es = read_measurement_index(tmp_path / "idx.csv")
    assert es[0].direction.tolist() == [0, 0, -1] and es[1].point.tolist() == [10, 0, -300]
    assert es[0].file == str(tmp_path / "a.csv")
    (tmp_path / "bad.csv").write_text("x,y,direction,file\n0,0,w,a.csv\n")
    with pytest.raises(InputError, match=r"bad\.csv: line 2: direction must be one of x, y"):
        read_measurement_index(tmp_path / "bad.csv")
