"""Never a traceback: the table and recording readers (identify, model, fit, simulate, sensor,
report) under malformed inputs, and one regression test per defect class they found.

The fuzz property (:func:`helpers.fuzz.assert_handled`): each command either succeeds, with
output that is sane (JSON that parses, finite numbers or an explicit null), or ends with
exit status 1 or 2 and a message that names the bad file. The inputs are drawn by
:mod:`helpers.fuzz_tables` from valid files (its seeds are checked here to give the right
answer first). The regression tests run the real command (in this process,
``helpers.cli_process.run_here``) and check the one line of each error: the file, the
line/column/key/channel, and what was expected.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from helpers.cli_process import assert_one_line_error, run_here
from helpers.fuzz import FuzzCase, assert_handled, run_case
from helpers.fuzz_tables import (
    FUZZ_CLASSES,
    K_TRUE,
    csv_text,
    identify_check,
    identify_files,
    model_seeds,
    report_data_json,
    sensor_recording,
    sensor_trace,
    write_mat_variables,
    write_tdms_channels,
    write_text_channels,
)
from hypothesis import given

from stiffmap.loads import forces_matrix, paper9


# --------------------------------------------------------------------------- output checks
def _numbers(obj):
    """Every number in a JSON value (booleans left out)."""
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield obj


def check_output(case: FuzzCase, stdout: str) -> None:
    """What a command that succeeded printed is sane: its JSON parses, its numbers are finite
    (unknown ones are null), and the result the command exists for is there."""
    if "--json" not in case.argv:
        assert stdout.strip(), "a command that succeeded printed nothing"
        return
    out = json.loads(stdout)
    assert all(math.isfinite(x) for x in _numbers(out)), "a non-finite number in the JSON output"
    cmd = case.argv[0]
    if cmd == "identify":
        K = np.array(out["K"], dtype=float)
        assert K.shape in ((3, 3), (6, 6)) and np.all(np.isfinite(K))
    elif cmd == "model":
        assert all(("error" in r) != ("K" in r) for r in out)
    elif cmd == "fit":
        assert all(p["estimate"] is not None for p in out["parameters"].values())
    elif cmd == "sensor":
        rows = out["recordings"] if isinstance(out, dict) else out
        for r in rows:
            assert ("error" in r) or r["static_error_um"] is not None, r
    elif cmd == "report":
        assert "index.html" in out["files"]
    elif cmd == "simulate":
        assert out["positions"] >= 1 and out["load_cases"] >= 3


# --------------------------------------------------------------------------- fuzz
@pytest.mark.fuzz
@pytest.mark.parametrize("fuzz_class", FUZZ_CLASSES, ids=[c.name for c in FUZZ_CLASSES])
def test_never_a_traceback(fuzz_class):
    @given(case=fuzz_class.cases)
    def check(case):
        o = run_case(case)
        assert_handled(case, o)
        if o.kind == "ok":
            check_output(case, o.stdout)

    check()


@pytest.mark.parametrize("as_json", [True, False])
def test_the_identify_check_refuses_a_p_printed_as_nan_out_of_range_or_against_its_flag(as_json):
    # The valid seed: exit 0, p tested and printed (JSON and text), no asymmetric flag; then the
    # same output with the p made nan, 1.5, or below 1 % without the flag: each one found.
    forces, disp = identify_files()
    argv = ("identify", "{dir}/forces.csv", "{dir}/displacements.csv", *(("--json",) if as_json else ()))
    case = FuzzCase({"forces.csv": forces.encode(), "displacements.csv": disp.encode()}, argv, None)
    o = run_case(case)
    assert o.kind == "ok" and identify_check(None, o) == "", o.stderr
    if as_json:
        p = json.loads(o.stdout)["asymmetry_p"]
        assert 0.01 <= p <= 1
        head, tail = o.stdout.split(f'"asymmetry_p": {p!r}', 1)
        bad = {"NaN": "printed 'NaN' as a value", "1.5": "outside [0, 1]", "0.004": "asymmetric flag missing"}
        written = {v: f'{head}"asymmetry_p": {v}{tail}' for v in bad}
    else:
        p = re.search(r"\(test p = ([^)]*)\)", o.stdout).group(1)
        bad = {"nan": "printed 'nan' as a value", "1.5": "outside [0, 1]", "0.004": "asymmetric flag missing"}
        written = {v: o.stdout.replace(f"(test p = {p})", f"(test p = {v})") for v in bad}
    for v, needle in bad.items():
        o.stdout = written[v]
        assert needle in identify_check(None, o), v


# --------------------------------------------------------------------------- the seeds are right
def _run(files: dict[str, bytes], *argv: str) -> dict | list:
    o = run_case(FuzzCase(files, argv, None))
    assert o.kind == "ok", o.stderr
    return json.loads(o.stdout)


def test_valid_seeds_give_the_right_answer():
    """The fuzzers start from inputs that are right: what they give is the truth within noise."""
    forces, disp = identify_files()
    out = _run(
        {"f.csv": forces.encode(), "d.csv": disp.encode()}, "identify", "{dir}/f.csv", "{dir}/d.csv", "--json"
    )
    # 2 um noise on displacements of about 2 mm: K within 1 %.
    assert np.linalg.norm(np.array(out["K"]) - K_TRUE) / np.linalg.norm(K_TRUE) < 0.01
    assert out["repeats"] == 2 and out["flags"] == []
    truth = sensor_trace().truth
    for fmt in ("csv", "txt", "semicolon", "tdms", "mat"):
        name = "rec" + {"txt": ".txt", "tdms": ".tdms", "mat": ".mat"}.get(fmt, ".csv")
        (row,) = _run({name: sensor_recording(fmt)}, "sensor", "{dir}/" + name, "--json")
        # 1 um noise, 7 plateaus of about 150 samples: the static error (500 um) within 3 um.
        assert row["static_error_um"] == pytest.approx(1e3 * truth.static_error_mm, abs=3.0), fmt
    seeds = model_seeds()
    fit = _run({"m.csv": seeds["static2"].encode()}, "fit", "3prr", "{dir}/m.csv", "--json")
    assert fit["parameters"]["kj"]["estimate"] == pytest.approx(525.0, rel=0.02)  # the default kj
    fit = _run({"m.csv": seeds["stiffness3"].encode()}, "fit", "delta", "{dir}/m.csv", "--json")
    assert fit["parameters"]["k_theta"]["estimate"] == pytest.approx(277000.0, rel=1e-6)
    for kind in ("sensor", "vision"):
        rep = _run(
            {"data.json": report_data_json(kind).encode()},
            "report",
            "{dir}/data.json",
            "{dir}/out",
            "--no-png",
            "--json",
        )
        assert "index.html" in rep["files"]


# --------------------------------------------------------------------------- regressions: identify
F9 = forces_matrix(paper9())
FORCES = csv_text(("fx", "fy", "fz"), F9.T, "{:.6g}")


def _identify(tmp_path, disp_text: str, forces_text: str = FORCES):
    f = tmp_path / "forces.csv"
    d = tmp_path / "displacements.csv"
    f.write_text(forces_text)
    d.write_text(disp_text)
    return run_here("identify", f, d, "--json")


def _disp(D) -> str:
    return csv_text(("dx", "dy", "dz"), np.asarray(D).T, "{:.17g}")


D_GOOD = np.linalg.solve(K_TRUE, F9) + np.random.default_rng(3).normal(scale=2e-3, size=F9.shape)


@pytest.mark.parametrize(
    "D, needles",
    [
        (np.zeros((3, 9)), ("every displacement is zero", "nothing moved")),
        (np.full((3, 9), 1e-300), ("every displacement is below 1e-09 mm", "are the displacements in mm")),
        (np.tile(D_GOOD[:, :1], 9), ("span rank 1 but 3 independent directions",)),
        (np.vstack([D_GOOD[:2], np.zeros(9)]), ("span rank 2", "a component always zero")),
    ],
    ids=["all zero", "all 1e-300", "the same for every load", "dz always zero"],
)
def test_identify_displacements_that_give_no_finite_stiffness(tmp_path, D, needles):
    """Were LinAlgError: Singular matrix (a bug, exit 3)."""
    proc = _identify(tmp_path, _disp(D))
    assert proc.returncode == 2
    assert_one_line_error(proc, "displacements.csv", *needles)


def test_identify_displacement_of_1e308_names_line_and_column(tmp_path):
    """Was ValueError: K contains NaN or infinite values (a bug)."""
    D = D_GOOD.copy()
    D[1, 3] = 1e308
    proc = _identify(tmp_path, _disp(D))
    assert_one_line_error(
        proc, "displacements.csv", "line 5, column 'dy'", "1e+308 mm is beyond +-1e+06 mm", "displacement"
    )


def test_identify_forces_too_small_for_the_displacements(tmp_path):
    """Forces of 1e-300 N: their ratio to the displacements overflows (was LinAlgError)."""
    proc = _identify(tmp_path, _disp(D_GOOD), csv_text(("fx", "fy", "fz"), F9.T * 1e-300, "{:.6g}"))
    assert_one_line_error(proc, "displacements.csv", "no finite stiffness", "beyond floating-point range")


def test_csv_cell_of_200000_digits(tmp_path):
    """Was _csv.Error: field larger than field limit (a bug)."""
    text = _disp(D_GOOD).splitlines()
    text[3] = "7" * 200_000 + ",0,0"
    proc = _identify(tmp_path, "\n".join(text) + "\n")
    assert_one_line_error(proc, "displacements.csv", "line 4", "not a table of numbers", "field larger")


@pytest.mark.parametrize(
    "data, needles",
    [
        (_disp(D_GOOD).encode("utf-16"), ("not UTF-8 text", "saved as UTF-8")),
        (_disp(D_GOOD).encode("utf-16-le"), ("not UTF-8 text", "NUL character", "UTF-16")),
        (_disp(D_GOOD).replace(".", ",").encode(), ("cells but the header has 3 columns", "decimal comma")),
    ],
    ids=["utf-16", "utf-16 without a byte-order mark", "decimal comma in a comma CSV"],
)
def test_csv_never_read_as_garbage(tmp_path, data, needles):
    """A UTF-16 file or decimal commas between comma separators are refused, not misread."""
    d = tmp_path / "displacements.csv"
    (tmp_path / "forces.csv").write_text(FORCES)
    d.write_bytes(data)
    assert_one_line_error(run_here("identify", tmp_path / "forces.csv", d), "displacements.csv", *needles)


# --------------------------------------------------------------------------- regressions: models
def test_model_points_and_fit_values_beyond_plausibility(tmp_path):
    """Were RuntimeWarning: overflow (a bug) in the models."""
    p = tmp_path / "points.csv"
    p.write_text("x,y,z\n0,0,-310\n1e300,0,-300\n")
    assert_one_line_error(
        run_here("model", "delta", "--points", p, "--json"),
        "points.csv",
        "line 3, column 'x'",
        "not a plausible position",
    )
    lines = model_seeds()["stiffness3"].splitlines()
    cells = lines[2].split(",")
    cells[4] = "1e308"  # k12 (x, y, z, k11, k12, ...)
    m = tmp_path / "meas.csv"
    m.write_text("\n".join([*lines[:2], ",".join(cells), *lines[3:]]) + "\n")
    assert_one_line_error(
        run_here("fit", "delta", m), "meas.csv", "line 3, column 'k12'", "not a plausible stiffness"
    )


def test_simulate_names_the_positions_file_of_an_unreachable_position(tmp_path):
    p = tmp_path / "positions.csv"
    p.write_text("x,y,z\n0,0,-310\n66.67,-66.67,0\n")
    proc = run_here("simulate", tmp_path / "out", "--truth-only", "--positions", p)
    assert_one_line_error(proc, "positions.csv", "position 2", "unreachable")

    # A load that pushes the board out of the camera's view names the loads file too.
    loads = tmp_path / "loads.csv"
    loads.write_text("fx,fy,fz\n0,4.905,0\n-4.905,0,0\n0,0,-4905\n")
    p.write_text("x,y,z\n0,0,-310\n")
    proc = run_here("simulate", tmp_path / "out2", "--truth-only", "--positions", p, "--loads", loads)
    line = assert_one_line_error(proc, "positions.csv", "position 1", "load 3", "leaves the image")
    assert line.endswith(f"(load 3 from {loads})"), line


# --------------------------------------------------------------------------- regressions: sensor
def _channels(**change):
    rec = sensor_trace().recording
    ch = {"time_s": rec.time_s, "displacement_v": rec.displacement_v, "load_kgf": rec.load}
    ch.update(change)
    return {k: v for k, v in ch.items() if v is not None}


@pytest.mark.parametrize("fmt", ["csv", "tdms", "mat"])
def test_constant_displacement_asks_whether_the_sensor_is_on_the_target(tmp_path, fmt):
    """Was ZeroDivisionError: float division by zero. This one will happen in a real lab."""
    ch = _channels(displacement_v=np.full(sensor_trace().recording.n, 1.234))
    data = {"csv": write_text_channels, "tdms": write_tdms_channels, "mat": write_mat_variables}[fmt](ch)
    f = tmp_path / f"laser.{fmt}"
    f.write_bytes(data)
    proc = run_here("sensor", f)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f"laser.{fmt}" in lines[0]
    assert (
        "the displacement (channel 'displacement_v') is constant over the whole recording "
        "(1.234 V on every sample)"
    ) in lines[0]
    assert "is the sensor on the target?" in lines[0]
    assert lines[1].startswith("error: none of the 1 recording(s) could be analysed")


#: An int16 DAQ's codes per volt (+-10 V over +-32768).
CODES_PER_V = 3276.8


def _int16_codes():
    return np.round(sensor_trace().recording.displacement_v * CODES_PER_V).astype(np.int16)


def _text(values, fmt="{:.4f} V"):
    return np.array([fmt.format(v) for v in values])


#: Recordings with a wrong type or an absurd value (built when the test runs), what the one
#: line about each must say.
WRONG_RECORDINGS = {
    "tdms wf_increment text": (
        "rec.tdms",
        lambda r: write_tdms_channels(_channels(time_s=None), {"wf_increment": "0.01 s"}, time_channel=False),
        ("channel 'displacement_v': property wf_increment = '0.01 s' is not a number of s",),
    ),
    "mat sample rate text": (
        "rec.mat",
        lambda r: write_mat_variables(_channels(time_s=None), {"sample_rate_hz": np.array("100 Hz")}),
        ("variable 'sample_rate_hz' = '100 Hz' is not a number of Hz",),
    ),
    "mat sample rate 0": (
        "rec.mat",
        lambda r: write_mat_variables(_channels(time_s=None), {"sample_rate_hz": 0.0}),
        ("variable 'sample_rate_hz': a sample rate of 0 Hz is not plausible",),
    ),
    "tdms wf_increment 0": (
        "rec.tdms",
        lambda r: write_tdms_channels(_channels(time_s=None), {"wf_increment": 0.0}, time_channel=False),
        ("property wf_increment = 0.0, expected > 0 s",),
    ),
    "tdms load channel of text": (
        "rec.tdms",
        lambda r: write_tdms_channels(_channels(load_kgf=np.array(["n/a"] * r.n))),
        ("channel 'load_kgf' holds text (first: 'n/a'), expected numbers",),
    ),
    "mat displacement of text": (
        "rec.mat",
        lambda r: write_mat_variables(_channels(displacement_v=_text(r.displacement_v))),
        ("variable 'displacement_v' holds text",),
    ),
    "tdms int16 displacement of raw codes": (
        "rec.tdms",
        lambda r: write_tdms_channels(_channels(displacement_v=_int16_codes())),
        (
            "the displacement (channel 'displacement_v') holds whole numbers",
            "beyond the sensor range of +-8 V",
            "raw DAQ codes",
        ),
    ),
    "mat int16 displacement of raw codes": (
        "rec.mat",
        lambda r: write_mat_variables(_channels(displacement_v=_int16_codes())),
        ("the displacement (channel 'displacement_v') holds whole numbers", "without their scale to volts"),
    ),
    "tdms load of 1e300": (
        "rec.tdms",
        lambda r: write_tdms_channels(_channels(load_kgf=r.load * 1e300)),
        ("load channel 'load_kgf'", "is beyond +-1e+09 N: not a plausible load"),
    ),
    "csv time step of 1e-302 s": (
        "rec.csv",
        lambda r: write_text_channels(_channels(time_s=r.time_s * 1e-300)),
        ("a sample rate of", "Hz is not plausible", "are the times in s?"),
    ),
}


@pytest.mark.parametrize("which", list(WRONG_RECORDINGS))
def test_recordings_with_wrong_types_and_absurd_values(tmp_path, which):
    """Were ValueError, ZeroDivisionError, OverflowError (bugs)."""
    name, build, needles = WRONG_RECORDINGS[which]
    f = tmp_path / name
    f.write_bytes(build(sensor_trace().recording))
    proc = run_here("sensor", f)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    first = proc.stderr.splitlines()[0]
    assert first.startswith(f"warning: {f}: ") and first.endswith("(skipped)"), first
    for n in needles:
        assert n in first, f"{n!r} not in {first!r}"


def test_an_int16_displacement_channel_is_read(tmp_path):
    """An int16 channel was a bug; a scaled one (NI_Scale properties, as DAQmx writes it) is
    read in volts, and one of small whole numbers is read as volts as it is."""
    scale = {
        "NI_Number_Of_Scales": 2,
        "NI_Scaling_Status": "unscaled",
        "NI_Scale[1]_Scale_Type": "Linear",
        "NI_Scale[1]_Linear_Slope": 1 / CODES_PER_V,
        "NI_Scale[1]_Linear_Y_Intercept": 0.0,
    }
    f = tmp_path / "rec.tdms"
    f.write_bytes(write_tdms_channels(_channels(displacement_v=_int16_codes()), scale, only="displacement_v"))
    proc = run_here("sensor", f, "--json")
    assert proc.returncode == 0, proc.stderr
    (row,) = json.loads(proc.stdout)
    # Quantised to 1/3276.8 V (0.2 um): the static error (500 um) within 3 um.
    assert row["static_error_um"] == pytest.approx(1e3 * sensor_trace().truth.static_error_mm, abs=3.0)
    # Whole volts (a coarse logger): read as numbers, the analysis goes on (and says the
    # steps are not resolved, or succeeds) -- never a refusal for the type.
    g = tmp_path / "coarse.mat"
    whole = np.round(sensor_trace().recording.displacement_v * 8).astype(np.int16)
    g.write_bytes(write_mat_variables(_channels(displacement_v=whole)))
    proc = run_here("sensor", g, "--json")
    assert "Traceback" not in proc.stderr and "holds" not in proc.stderr, proc.stderr


def test_an_int16_load_in_kgf_is_read_as_whole_numbers(tmp_path):
    """A dynamometer's whole-number readings are numbers of its unit, not DAQ codes."""
    f = tmp_path / "rec.tdms"
    f.write_bytes(
        write_tdms_channels(_channels(load_kgf=np.round(sensor_trace().recording.load).astype(np.int16)))
    )
    proc = run_here("sensor", f, "--json")
    assert proc.returncode == 0, proc.stderr
    (row,) = json.loads(proc.stdout)
    assert row["static_error_um"] == pytest.approx(1e3 * sensor_trace().truth.static_error_mm, abs=3.0)


def test_a_damaged_mat_file_is_refused_not_a_crash(tmp_path):
    """SciPy's reader dies (segmentation fault) on a data element whose type code is no MATLAB
    type: the file is checked first and refused, and the other recordings go on."""
    data = bytearray(sensor_recording("mat"))
    # The first variable's data tag (time_s: flags, dimensions and name take 56 bytes) zeroed.
    data[184:192] = bytes(8)
    bad = tmp_path / "bad.mat"
    bad.write_bytes(bytes(data))
    good = tmp_path / "good.tdms"
    good.write_bytes(sensor_recording("tdms"))
    proc = run_here("sensor", good, bad, "--json")
    assert proc.returncode == 1, proc.stderr  # one analysed, one refused
    assert_one_line_error(
        proc, "bad.mat", "not a readable MATLAB .mat file (damaged:", "variable 'time_s'", "type code 0"
    )
    rows = json.loads(proc.stdout)
    assert "static_error_um" in rows[0] and set(rows[1]) == {"file", "error"}


def test_json_output_still_names_each_failed_recording(tmp_path):
    """With --json the failures were only in the JSON: exit 2 without a message."""
    f = tmp_path / "empty.csv"
    f.write_text("time_s,displacement_v,load_kgf\n")
    proc = run_here("sensor", f, "--json")
    assert proc.returncode == 2
    assert json.loads(proc.stdout)[0]["error"].startswith(str(f))
    assert [ln.split(":")[0] for ln in proc.stderr.splitlines()] == ["warning", "error"]
    assert "empty.csv" in proc.stderr.splitlines()[0]


@pytest.mark.parametrize(
    "option, needles",
    [
        (("--range-v", "0.005"), ("--range-v must exceed the saturation margin of 0.01 V",)),
        (("--steps-kgf", "0,1e300,0"), ("--steps-kgf: 1e+300 kgf is beyond +-1e+09 N",)),
        (("--load-n-per-v", "1e-300"), ("--load-n-per-v must be between 1e-09 and 1e+09 N/V",)),
        (
            ("--channel-map", "rate=1e300,time=none"),
            ("rate=1e300: a sample rate of 1e+300 Hz is not plausible",),
        ),
    ],
    ids=["range below the saturation margin", "absurd step", "load-cell scale", "absurd rate"],
)
def test_sensor_options_out_of_range_name_the_option(tmp_path, option, needles):
    """--range-v below the margin was ValueError (a bug); the others were overflows."""
    f = tmp_path / "rec.csv"
    f.write_bytes(sensor_recording("csv"))
    assert_one_line_error(run_here("sensor", f, *option), *needles)


def test_index_names_its_line_for_a_bad_recording_name_or_point(tmp_path):
    idx = tmp_path / "index.csv"
    idx.write_text("x,y,ux,uy,file\n400,200,1,0,rec.tdms\n400,200,0,1,rec.tmds\n")
    assert_one_line_error(
        run_here("sensor", "--index", idx),
        "index.csv",
        "line 3, column 'file'",
        "unknown recording format",
    )
    idx.write_text("x,y,ux,uy,file\n400,200,1e308,1e308,rec.tdms\n1e300,200,0,1,rec.tdms\n")
    assert_one_line_error(
        run_here("sensor", "--index", idx), "index.csv", "line 3", "not a plausible position"
    )


# --------------------------------------------------------------------------- regressions: report
@pytest.mark.parametrize(
    "change, needles",
    [
        ("1" + "0" * 400, ("sensor.error_um", "beyond the range of floating point")),
        ("1e308", ("sensor.error_um", "1e+308 is beyond", "not a plausible value")),
    ],
    ids=["an integer of 401 digits", "1e308 um"],
)
def test_report_data_json_with_numbers_beyond_float(tmp_path, change, needles):
    """Were OverflowError: int too large to convert to float, and overflow in the figures."""
    obj = json.loads(report_data_json("sensor"))
    text = json.dumps(obj).replace(json.dumps(obj["sensor"]["error_um"]), f"[{change}, 1, 2, 3, 4, 5, 6, 7]")
    f = tmp_path / "data.json"
    f.write_text(text)
    assert_one_line_error(run_here("report", f, tmp_path / "out", "--no-png"), "data.json", *needles)


def test_a_damaged_tdms_file_gives_one_line_not_nptdms_log_lines(tmp_path):
    """npTDMS printed its own ``[nptdms.reader WARNING]`` lines to stderr beside stiffmap's."""
    data = bytearray(sensor_recording("tdms"))
    f = tmp_path / "truncated.tdms"
    f.write_bytes(bytes(data[:-5000]))
    proc = run_here("sensor", f)
    assert "[nptdms" not in proc.stderr, proc.stderr
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 2, proc.stderr
    assert "truncated.tdms: load channel 'load_kgf' has" in proc.stderr
    # A damaged property name: npTDMS reads the file; one warning says it was not clean (and a
    # warning makes the exit status 1: done, with warnings).
    i = data.find(b"unit_string")
    data[i + 10] = 0xE8
    # (In-process: the subprocess harness runs with every warning an error.)
    o = run_case(FuzzCase({"damaged.tdms": bytes(data)}, ("sensor", "{dir}/damaged.tdms", "--json"), None))
    assert o.kind == "clear" and o.code == 1, o.stderr
    (line,) = o.stderr.strip().splitlines()
    assert line.startswith("warning: ") and "damaged.tdms: npTDMS: Error decoding string" in line
    assert "damaged or truncated file?" in line


def test_simulate_writes_a_load_label_with_a_control_character_as_valid_toml(tmp_path):
    """A label holding a control character was written into campaign.toml as it was, which
    then failed to parse: 'campaign.toml: not valid TOML: Illegal character' (not the CSV)."""
    import tomllib

    loads = tmp_path / "loads.csv"
    loads.write_bytes(b"fx,fy,fz,label\n0,4.905,0,\x01.5 kg +y\n-4.905,0,0,0.5 kg -x\n0,0,-4.905,0.5 kg -z\n")
    pos = tmp_path / "positions.csv"
    pos.write_text("x,y,z\n0,0,-310\n")
    out = tmp_path / "out"
    proc = run_here("simulate", out, "--truth-only", "--loads", loads, "--positions", pos, "--json")
    assert proc.returncode == 0, proc.stderr
    text = (out / "campaign.toml").read_text()
    assert "\x01" not in text and "\\u0001.5 kg +y" in text
    tomllib.loads(text)
