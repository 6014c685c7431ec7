"""Readers and writers of recordings: CSV, TDMS, MAT; the channel map; file errors."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import scipy.io
from helpers.sensor_traces import quick_trace
from nptdms import ChannelObject, GroupObject, RootObject, TdmsFile, TdmsWriter

from stiffmap.errors import InputError
from stiffmap.io import dumps_json
from stiffmap.sensors import (
    ChannelMap,
    Recording,
    SensorConfig,
    analyse_recording,
    parse_channel_map,
    read_recording,
    write_recording,
)
from stiffmap.sim.traces import LoadSteps


def test_a_mat_recording_written_at_two_times_is_the_same_file(tmp_path, monkeypatch):
    """SciPy writes the time of day into a MAT file's header: stiffmap fixes it, so the same
    seed gives the same bytes (simulate's promise)."""
    import time

    tr = quick_trace(0.3, seed=3)
    a = write_recording(tr.recording, tmp_path / "a.mat").read_bytes()
    monkeypatch.setattr(time, "asctime", lambda *_: "Thu Jan  1 00:00:00 2099")
    b = write_recording(tr.recording, tmp_path / "b.mat").read_bytes()
    assert a == b
    np.testing.assert_array_equal(
        read_recording(tmp_path / "b.mat").displacement_v, tr.recording.displacement_v
    )


@pytest.mark.parametrize("load_channel", [True, False])
def test_same_recording_as_csv_tdms_mat_gives_identical_results(tmp_path, load_channel):
    """The issue's must-show: one recording stored in the three formats analyses identically."""
    tr = quick_trace(
        0.8, seed=11, protocol=LoadSteps(plateau_s=2.0, transition_s=0.8, load_channel=load_channel)
    )
    cfg = SensorConfig(steps=None if load_channel else tr.truth.steps)
    dicts = {}
    for fmt in ("csv", "tdms", "mat"):
        p = write_recording(tr.recording, tmp_path / f"rec.{fmt}")
        rec = read_recording(p)
        # Bit-for-bit the same samples as simulated.
        np.testing.assert_array_equal(rec.time_s, tr.recording.time_s)
        np.testing.assert_array_equal(rec.displacement_v, tr.recording.displacement_v)
        if load_channel:
            np.testing.assert_array_equal(rec.load, tr.recording.load)
            assert rec.load_unit == "kgf"
        else:
            assert rec.load is None
        d = analyse_recording(rec, cfg).to_dict()
        d.pop("file")
        dicts[fmt] = dumps_json(d)  # NaN (a table's load std) as null, so equal means equal
    assert dicts["csv"] == dicts["tdms"] == dicts["mat"]
    # ... and the numbers are right (truth of the simulation), so they are not identically wrong.
    est = json.loads(dicts["csv"])["static_error_um"]
    assert abs(est - 1e3 * tr.truth.static_error_mm) <= 1 + 0.01 * 800


@pytest.mark.parametrize("sep, decimal", [("\t", "."), (";", ","), ("\t", ",")])
def test_tab_and_semicolon_separated_text_reads_like_the_csv(tmp_path, sep, decimal):
    """DAQ software writes tab-separated .txt; spreadsheets in many locales write ';' and 1,25."""
    tr = quick_trace(0.8, seed=5)
    csv_path = write_recording(tr.recording, tmp_path / "rec.csv")
    lines = csv_path.read_text().splitlines()
    converted = [lines[0].replace(",", sep)]
    for row in lines[1:]:
        cells = [c.replace(".", decimal) for c in row.split(",")]
        converted.append(sep.join(cells))
    txt = tmp_path / "rec.txt"
    txt.write_text("\n".join(converted) + "\n")
    a, b = read_recording(csv_path), read_recording(txt)
    np.testing.assert_array_equal(b.time_s, a.time_s)
    np.testing.assert_array_equal(b.displacement_v, a.displacement_v)
    np.testing.assert_array_equal(b.load, a.load)


def test_tdms_waveform_without_time_channel_and_with_gap(tmp_path):
    tr = quick_trace(0.3, seed=2)
    p = write_recording(tr.recording, tmp_path / "w.tdms")
    f = TdmsFile.read(p)
    names = [c.name for c in f["daq"].channels()]
    assert "time_s" not in names  # uniform sampling: written as a waveform (wf_increment)
    assert f["daq"]["displacement_v"].properties["wf_increment"] == pytest.approx(1 / 500.0, rel=1e-15)
    # A recording with missing samples cannot be a waveform: a time channel is written.
    gap = quick_trace(0.3, seed=2, dropouts=[(3.0, 3.2)], dropout_kind="gap")
    p2 = write_recording(gap.recording, tmp_path / "g.tdms")
    rec = read_recording(p2)
    assert "time_s" in [c.name for c in TdmsFile.read(p2)["daq"].channels()]
    np.testing.assert_array_equal(rec.time_s, gap.recording.time_s)
    assert np.diff(rec.time_s).max() == pytest.approx(0.202, abs=0.0021)


def test_channel_map_custom_names_in_each_format(tmp_path):
    rng = np.random.default_rng(3)
    n = 200
    t = np.arange(n) / 100.0
    v = rng.normal(size=n)
    f = rng.uniform(0, 50, size=n)
    cmap = parse_channel_map("displacement=LDV,load=force_n,time=t")
    assert cmap == ChannelMap("LDV", "force_n", "t", load_required=True, time_required=True)
    # CSV with other columns around.
    (tmp_path / "a.csv").write_text(
        "# recorded by hand\nt,other,LDV,force_n\n"
        + "".join(f"{a:.17g},1,{b:.17g},{c:.17g}\n" for a, b, c in zip(t, v, f, strict=True))
    )
    # TDMS in a group of its own, MAT as fields of a struct.
    with TdmsWriter(tmp_path / "a.tdms") as w:
        w.write_segment(
            [
                RootObject(),
                GroupObject("run1"),
                ChannelObject("run1", "t", t),
                ChannelObject("run1", "LDV", v),
                ChannelObject("run1", "force_n", f),
            ]
        )
    scipy.io.savemat(tmp_path / "a.mat", {"rec": {"t": t, "LDV": v, "force_n": f}})
    for name, cm in (("a.csv", cmap), ("a.tdms", cmap), ("a.mat", dataclasses.replace(cmap, group="rec"))):
        rec = read_recording(tmp_path / name, cm)
        np.testing.assert_array_equal(rec.time_s, t)
        np.testing.assert_array_equal(rec.displacement_v, v)
        np.testing.assert_array_equal(rec.load, f)
        assert rec.load_unit == "N", name  # from the column's suffix


def test_no_time_column_uses_the_rate(tmp_path):
    (tmp_path / "r.csv").write_text("displacement_v\n" + "\n".join(["0.5"] * 50) + "\n")
    rec = read_recording(tmp_path / "r.csv", parse_channel_map("time=none,rate=250,load=none"))
    np.testing.assert_allclose(rec.time_s, np.arange(50) / 250.0, rtol=0, atol=1e-15)
    with pytest.raises(InputError, match=r"r\.csv: no time channel .*rate=HZ"):
        read_recording(tmp_path / "r.csv")
    scipy.io.savemat(tmp_path / "r.mat", {"displacement_v": np.zeros(40), "sample_rate_hz": 2000.0})
    rec = read_recording(tmp_path / "r.mat")
    assert rec.sample_rate_hz == pytest.approx(2000.0, rel=1e-12)


#: (file, content: text, bytes, MAT variables or None for no file, --channel-map, expected message)
_BAD_RECORDINGS = [
    ("nope.csv", None, None, r"nope\.csv: file not found"),
    ("x.xlsx", "", None, r"unknown recording format '\.xlsx'"),
    ("c.csv", "time_s,volts\n0,1\n0.1,2\n", None, r"c\.csv: missing column 'displacement_v'"),
    (
        "d.csv",
        "time_s,displacement_v\n0,1\n0.1,abc\n",
        None,
        r"d\.csv: line 3, column 'displacement_v': 'abc' is not a number",
    ),
    (
        "e.csv",
        "time_s,displacement_v\n0,1\n0.2,2\n0.1,3\n",
        None,
        r"e\.csv: time must increase: sample 2 at 0\.1 s follows 0\.2 s",
    ),
    ("f.csv", "time_s,displacement_v\n0,1\n0.1,2\n", "load=load_n", r"f\.csv: missing column 'load_n'"),
    ("bad.tdms", b"this is not a TDMS file at all" * 4, None, r"bad\.tdms: not a readable TDMS file"),
    ("bad.mat", b"\x00\x01garbage" * 20, None, r"bad\.mat: not a readable MATLAB \.mat file"),
    (
        "m.mat",
        {"time_s": np.arange(5.0), "displacement_v": np.zeros(4)},
        None,
        r"m\.mat: variable 'time_s' has 5 samples, 'displacement_v' has 4",
    ),
]


@pytest.mark.parametrize(
    ("name", "content", "channel_map", "message"), _BAD_RECORDINGS, ids=[c[0] for c in _BAD_RECORDINGS]
)
def test_reader_errors_name_the_file_and_the_channel(tmp_path, name, content, channel_map, message):
    p = tmp_path / name
    if isinstance(content, str):
        p.write_text(content)
    elif isinstance(content, bytes):
        p.write_bytes(content)
    elif isinstance(content, dict):
        scipy.io.savemat(p, content)
    args = () if channel_map is None else (parse_channel_map(channel_map),)
    with pytest.raises(InputError, match=message):
        read_recording(p, *args)


def test_channel_map_names_an_unknown_key():
    with pytest.raises(InputError, match=r"unknown key 'volts'"):
        parse_channel_map("volts=a")


def test_recording_checks_its_arrays():
    with pytest.raises(InputError, match="time has 3 samples but the displacement has 2"):
        Recording("r", [0, 1, 2], [0, 1])
    with pytest.raises(InputError, match="time of sample 1 is not a finite number"):
        Recording("r", [0, np.nan, 2], [0, 1, 2])


def test_tdms_channel_in_two_groups_asks_for_the_group(tmp_path):
    t = np.arange(100) / 100.0
    with TdmsWriter(tmp_path / "two.tdms") as w:
        w.write_segment(
            [
                RootObject(),
                GroupObject("a"),
                GroupObject("b"),
                ChannelObject("a", "displacement_v", t),
                ChannelObject("b", "displacement_v", -t),
                ChannelObject("a", "time_s", t),
            ]
        )
    with pytest.raises(InputError, match=r"channel 'displacement_v' is in several groups \('a', 'b'\)"):
        read_recording(tmp_path / "two.tdms")
    rec = read_recording(tmp_path / "two.tdms", parse_channel_map("group=b,time=none,rate=100"))
    np.testing.assert_array_equal(rec.displacement_v, -t)
    with pytest.raises(InputError, match=r"no TDMS group 'c' \(groups: 'a', 'b'\)"):
        read_recording(tmp_path / "two.tdms", parse_channel_map("group=c"))
