"""``stiffmap compensate``: bad input is one line naming what is wrong and nothing written; a good run
writes the program, its figures and a summary; a campaign's fitted model compensates the test-bed.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from helpers.cli_process import run_in_process, run_stiffmap
from helpers.fuzz import FuzzCase, assert_handled, mutated_text, run_case
from helpers.fuzz_machining import campaign_files, edited_db
from helpers.machining_checks import arm_deflection, distance_to_path, output_samples, truss_3prr
from hypothesis import given, settings
from hypothesis import strategies as st

from stiffmap.machining.io import read_program
from stiffmap.machining.path import toolpath_from_moves
from stiffmap.models import arm6
from stiffmap.models.chain import Chain

DATA = Path(__file__).parent / "data" / "gcode"
PROGRAM = DATA / "own_cam_mm.nc"


def _one_line(code, err, *needles):
    assert code == 2, err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], lines[0]


def _run_3prr(program, out, monkeypatch, capsys, *args, place="380,200", force=("--force-n", "0,-490.5")):
    """``stiffmap compensate 3prr PROGRAM`` (quiet) placed at ``place``, under ``force``, then ``args``."""
    argv = ["compensate", "3prr", "--path", program, "--out", out, "-q", "--place", place, *force, *args]
    return run_in_process(argv, monkeypatch, capsys)


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (
            ["--place", "380,200", "--force-n", "0,-490.5", "--tolerance-um", "0"],
            ["--tolerance-um", "positive"],
        ),
        (["--place", "0,0", "--force-n", "0,-490.5"], ["line 12:", "unreachable", "nothing written"]),
        (["--place", "380,200", "--force-n", "0,-490.5,1,2"], ["--force-n", "2 or 3"]),
        (["--place", "380,200"], ["no force"]),
    ],
)
def test_bad_options_are_one_line_and_write_nothing(tmp_path, monkeypatch, capsys, args, needles):
    out = tmp_path / "out.nc"
    code, _, err = run_in_process(
        ["compensate", "3prr", "--path", PROGRAM, "--out", out, "-q", *args], monkeypatch, capsys
    )
    _one_line(code, err, *needles)
    assert list(tmp_path.iterdir()) == []


def test_unsupported_construct_and_force_rows(tmp_path, monkeypatch, capsys):
    prog = tmp_path / "cycle.nc"
    prog.write_text("G21 G90\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X10\nG81 X5 Y5 Z-2 R1\nG80\n")
    out = tmp_path / "out.nc"
    base = ["compensate", "3prr", "--path", prog, "--out", out, "-q", "--place", "380,200"]
    code, _, err = run_in_process([*base, "--force-n", "0,-490.5"], monkeypatch, capsys)
    _one_line(code, err, "cycle.nc: line 5:", "canned cycle G81", "--pass-through")
    forces = tmp_path / "f.csv"
    forces.write_text("line,fx,fy\n3,0,-400\n")
    prog.write_text("G21 G90\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X10\n")
    code, _, err = run_in_process([*base, "--force-file", forces], monkeypatch, capsys)
    _one_line(code, err, "f.csv", "1 force row(s), but the program has 2 feed move(s)")
    assert not out.exists()
    forces.write_text("line,fx,fy\n3,0,-400\n4,0,-400\n")
    code, _, err = run_in_process([*base, "--force-file", forces, "--no-figures"], monkeypatch, capsys)
    assert code == 0, err
    assert out.exists()


def test_a_good_run_writes_program_figures_and_summary(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out.nc"
    code, stdout, err = run_in_process(
        [
            "compensate",
            "3prr",
            "--param",
            "area=100",
            "--path",
            PROGRAM,
            "--out",
            out,
            "--json",
            "--place",
            "380,200",
            "--force-feed-n",
            "300,200",
        ],
        monkeypatch,
        capsys,
    )
    assert code == 0, err
    s = json.loads(stdout)
    assert s["residual_after_um"]["worst"] <= 1.0 < s["deflection_before_um"]["worst"]
    assert s["corrected_axes"] == "xy" and s["place_mm"] == [380.0, 200.0, 0.0]
    assert sorted(Path(p).name for p in s["written"]) == ["out.nc", "out.nc.deflection.png", "out.nc.html"]
    text = out.read_text()
    assert text.splitlines()[:3] == PROGRAM.read_text().splitlines()[:3]  # header lines kept verbatim


def test_a_good_run_prints_nothing_on_stderr_without_a_terminal(tmp_path, monkeypatch, capsys):
    """Without -q, on a pipe or a log: no progress bar, and none of the empty line a transient
    bar left on stderr (before every summary and every error)."""
    out = tmp_path / "out.nc"
    args = ["compensate", "3prr", "--path", PROGRAM, "--out", out, "--no-figures", "--force-n", "0,-490.5"]
    code, stdout, err = run_in_process([*args, "--place", "380,200"], monkeypatch, capsys)
    assert (code, err) == (0, ""), err
    assert "worst predicted residual after" in stdout
    code, _, err = run_in_process([*args, "--place", "0,0"], monkeypatch, capsys)
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1, repr(err)


@pytest.mark.long  # a campaign simulated and run end to end: about 25 s
def test_from_campaign_compensates_the_test_bed(tmp_path):
    """A 3PRR sensor campaign on the test-bed (true kj 700 N/mm, not the published 525) identifies
    the model; the program it compensates, cut by the true robot (the truss of the helpers), errs by
    less than 10 % of the uncompensated program's worst error."""
    camp = tmp_path / "camp"
    sim = run_stiffmap(
        "simulate",
        camp,
        "--robot",
        "3prr",
        "--seed",
        "3",
        "--select",
        "2,8,19",
        "--repeats",
        "1",
        "--param",
        "kj=700",
    )
    assert sim.returncode == 0, sim.stderr
    run = run_stiffmap("run", camp, "-q", "--no-report")
    assert run.returncode == 0, run.stderr
    out = tmp_path / "out.nc"
    proc = run_stiffmap(
        "compensate",
        "--from-campaign",
        camp,
        "--path",
        PROGRAM,
        "--out",
        out,
        "--json",
        "--place",
        "380,200",
        "--force-n",
        "0,-490.5",
        "--no-figures",
        "--tolerance-um",
        "2",
    )
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["residual_band_95_um"] is not None and s["residual_band_95_um"] < 5.0
    true = {"h": 800.0, "L": 250.0, "EA": 70000.0 * 200.0, "kj": 700.0, "kb": 9800.0}
    F = np.array([0.0, -490.5])
    prog = toolpath_from_moves(read_program(PROGRAM)[0].moves)
    _, _, P = output_samples(prog)
    before = np.linalg.norm(truss_3prr(P[:, :2] + [380.0, 200.0], F, **true), axis=1).max()
    _, _, C = output_samples(toolpath_from_moves(read_program(out)[0].moves))
    D = C.copy()
    D[:, :2] += truss_3prr(C[:, :2] + [380.0, 200.0], F, **true)
    after = distance_to_path(prog, D).max()
    assert after < 0.1 * before, f"compensated {after:.4f} mm, uncompensated {before:.4f} mm"


_FORCES = "line,fx,fy\n15,0,-490.5\n16,0,-490.5\n"


@pytest.mark.fuzz
@settings(max_examples=25, deadline=None)
@given(
    which=st.sampled_from(["program", "forces"]),
    data=st.data(),
)
def test_malformed_inputs_are_handled(which, data):
    """A mutated program or force file: a corrected program, or one clear error line (exit 2)."""
    prog = PROGRAM.read_bytes()
    short = b"".join(prog.splitlines(keepends=True)[:17])  # up to the second feed move (line 16)
    forces = _FORCES.encode()
    if which == "program":
        short = data.draw(mutated_text(short.decode()))
    else:
        forces = data.draw(mutated_text(_FORCES))
    case = FuzzCase(
        {"p.nc": short, "f.csv": forces},
        (
            "compensate",
            "3prr",
            "--path",
            "{dir}/p.nc",
            "--out",
            "{dir}/o.nc",
            "--place",
            "380,200",
            "--force-file",
            "{dir}/f.csv",
            "-q",
            "--no-figures",
        ),
        None,  # a mutated program can change its feed moves: the force file is then to blame
    )
    assert_handled(case, run_case(case))


def test_a_platform_that_turns_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """A dim = 6 legs file (the shipped hexapod): its points are poses, which a three-axis
    program does not give; one line naming the file and exit 2, not an internal error."""
    hexapod = Path(__file__).parents[1] / "src" / "stiffmap" / "models" / "robots" / "hexapod.toml"
    out = tmp_path / "out.nc"
    args = ["compensate", "legs", hexapod, "--path", PROGRAM, "--out", out, "-q"]
    code, _, err = run_in_process([*args, "--place", "0,0,300", "--force-n", "0,0,-10"], monkeypatch, capsys)
    _one_line(code, err, "hexapod", "dim = 6")
    assert list(tmp_path.iterdir()) == []


# Findings of the fuzzing of compensate (tests/helpers/fuzz_machining.py, issue 31): each failed
# on the code before its fix.


def test_a_delta_compensates_a_csv_of_points_with_z(tmp_path):
    """x,y,z points for a spatial robot (z both required and optional) were an internal error."""
    from helpers.fuzz import run_argv, write_case
    from helpers.fuzz_machining import check_compensation, compensate_case, points_seed

    for forces in (False, True):
        opts = ("--place", "-40,-30,-300") + (() if forces else ("--force-n", "4,3,-2"))
        case = compensate_case(
            {"p.csv": points_seed(forces, planar=False).encode()}, "delta", "p.csv", *opts, out="o.csv"
        )
        d = tmp_path / str(forces)
        d.mkdir()
        o = run_argv(write_case(case, d))
        assert o.code == 0, o.stderr
        assert check_compensation(case, d, o) == ""  # on the path, deflected, by the independent solver


def test_a_place_far_outside_the_workspace_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """--place 1e9,1e9 was an internal error (the model's plausibility check, a ValueError)."""
    out = tmp_path / "out.nc"
    code, _, err = _run_3prr(PROGRAM, out, monkeypatch, capsys, place="1e9,1e9")
    _one_line(code, err, "own_cam_mm.nc: line 12:", "(1e+09, 1e+09)", "beyond")
    assert list(tmp_path.iterdir()) == []


def test_an_unplaced_program_out_of_reach_names_the_place_option(tmp_path, monkeypatch, capsys):
    """Without --place the program's origin is the base frame's: the 3PRR cannot reach (0, 0),
    which was said without saying why the program was there. The library's error names its
    placement fields (a FieldError), the command words them as --place; with --place 0,0 given,
    the same point is only out of reach (the user put it there)."""
    from stiffmap.errors import FieldError
    from stiffmap.machining import CompensateOptions, ForceSpec, compensate_file
    from stiffmap.models import PRR3

    out = tmp_path / "out.nc"
    opts = CompensateOptions(force=ForceSpec.constant([0.0, -490.5]))
    with pytest.raises(FieldError) as exc:
        compensate_file(PRR3(area=100.0), PROGRAM, out, opts)
    assert exc.value.fields == ("place_mm", "place_auto")
    assert "unless place_mm or place_auto is given" in str(exc.value)
    args = ["compensate", "3prr", "--path", PROGRAM, "--out", out, "-q", "--force-n", "0,-490.5"]
    code, _, err = run_in_process(args, monkeypatch, capsys)
    _one_line(
        code,
        err,
        "own_cam_mm.nc: line 12: programmed point (0, 0) mm (base frame) unreachable: ",
        "the program's origin is at the base frame's origin unless --place X,Y[,Z] or --place auto is given",
    )
    code, _, err = _run_3prr(PROGRAM, out, monkeypatch, capsys, place="0,0")
    _one_line(code, err, "own_cam_mm.nc: line 12:", "unreachable")
    assert "--place" not in err
    assert list(tmp_path.iterdir()) == []


def test_out_onto_the_program_is_refused_and_the_program_kept(tmp_path, monkeypatch, capsys):
    """--out the program itself overwrote the program with its compensated version."""
    prog = tmp_path / "p.nc"
    prog.write_bytes(PROGRAM.read_bytes())
    code, _, err = _run_3prr(prog, prog, monkeypatch, capsys)
    _one_line(code, err, "--out", "the program itself")
    assert prog.read_bytes() == PROGRAM.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.nc"]
    forces = tmp_path / "f.csv"  # nor the force file (it was overwritten by the program)
    forces.write_text(_FORCES)
    short = tmp_path / "s.nc"
    short.write_bytes(b"".join(PROGRAM.read_bytes().splitlines(keepends=True)[:17]))
    args = ["compensate", "3prr", "--path", short, "--out", forces, "-q", "--place", "380,200"]
    code, _, err = run_in_process([*args, "--force-file", forces], monkeypatch, capsys)
    _one_line(code, err, "--out", "the force file itself")
    assert forces.read_text() == _FORCES


def test_warnings_and_unreachable_points_name_the_program(tmp_path, monkeypatch, capsys):
    """The program's warnings ("X was never set") and a point out of reach named a line, not the file."""
    out = tmp_path / "out.nc"
    base = ["compensate", "3prr", "--out", out, "-q", "--no-figures", "--force-n", "0,-490.5"]
    code, _, err = run_in_process(
        [*base, "--path", DATA / "cncjs_circle-inch.gcode", "--place", "380,200"], monkeypatch, capsys
    )
    assert code == 1, err
    warnings = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 2 and all("cncjs_circle-inch.gcode: line 2:" in w for w in warnings), err
    code, _, err = run_in_process([*base, "--path", PROGRAM, "--place", "0,0"], monkeypatch, capsys)
    _one_line(code, err, "own_cam_mm.nc: line 12:", "unreachable")


@pytest.mark.parametrize("tolerance", ["0.1", "0.02"])
def test_a_fine_tolerance_is_honoured_by_the_written_program(tmp_path, tolerance):
    """--tolerance-um 0.1 on an inch program gave a program 0.19 um off the path (its coordinates
    written to 0.25 um); now written with the digits the tolerance needs, re-checked by the
    independent solver."""
    from helpers.fuzz import run_argv, write_case
    from helpers.fuzz_machining import check_compensation, compensate_case

    name = "own_inch_r_planes.nc"
    case = compensate_case(
        {"p.nc": (DATA / name).read_bytes()},
        "3prr",
        "p.nc",
        "--place",
        "380,200",
        "--force-n",
        "0,-490.5",
        "--tolerance-um",
        tolerance,
    )
    o = run_argv(write_case(case, tmp_path))
    assert o.code == 0, o.stderr
    assert check_compensation(case, tmp_path, o) == ""


def test_a_tolerance_below_ten_nanometres_is_refused(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out.nc"
    code, _, err = _run_3prr(PROGRAM, out, monkeypatch, capsys, "--tolerance-um", "1e-9")
    _one_line(code, err, "--tolerance-um", "below 0.01 um")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("line", "needles"),
    [
        ("G1 X" + "9" * 400, ["p.nc: line 3:", "X999999999999...", "beyond 1e+09"]),  # inf: NaN arcs
        ("G" + "7" * 320 + " G1 X5", ["p.nc: line 3:", "beyond 1e+09"]),  # int(inf): OverflowError
    ],
)
def test_numbers_of_hundreds_of_digits_are_refused(line, needles):
    """A word of hundreds of digits is infinite in floating point: it was an internal error."""
    from helpers.fuzz import run_case
    from helpers.fuzz_machining import compensate_case

    text = f"G21 G90\nG0 X0 Y0\n{line}\nG1 Y5 F100\n".encode()
    case = compensate_case(
        {"p.nc": text}, "3prr", "p.nc", "--place", "380,200", "--force-n", "0,-490.5", blamed="p.nc"
    )
    o = run_case(case)
    assert o.kind == "clear" and o.code == 2, (o.kind, o.stderr)
    _one_line(o.code, o.stderr, *needles)


def test_an_arc_as_the_first_move_is_refused(tmp_path, monkeypatch, capsys):
    """An arc from wherever the machine stands, then a cut: its entry had no centre (internal error)."""
    prog = tmp_path / "p.nc"
    prog.write_text("G3 X0 Y0 I0 J-5\nG21 G90\nG1 X10 Y0 F100\nG1 X20\n")
    out = tmp_path / "o.nc"
    code, _, err = _run_3prr(prog, out, monkeypatch, capsys)
    _one_line(code, err, "p.nc: line 1:", "an arc (G3) as the first move")
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--tool-rpy-deg", "0,180,0"], ["--tool-rpy-deg is for a serial arm"]),
        (["--q-seed-deg", "0,0,0"], ["--q-seed-deg is for a serial arm"]),
        (["--place-region", "0:1,0:1"], ["--place-region is for --place auto"]),
        (["--objective", "rms"], ["--objective is for --place auto"]),
        (["--objective", "best"], ["--objective must be worst or rms", "'best'"]),
    ],
)
def test_options_the_run_would_ignore_are_refused(tmp_path, monkeypatch, capsys, args, needles):
    """These were silently ignored (exit 0, a program written as without them): a tool orientation or
    seed joints for the 3PRR, a region or an objective (even 'best') with --place X,Y."""
    out = tmp_path / "out.nc"
    code, _, err = _run_3prr(PROGRAM, out, monkeypatch, capsys, *args)
    _one_line(code, err, *needles)
    assert list(tmp_path.iterdir()) == []


def test_a_force_that_pushes_the_commanded_point_out_of_reach_names_the_force_file(
    tmp_path, monkeypatch, capsys
):
    """A force row of 1e7 N (the 3PRR would deflect by metres): the error named the program's line only,
    as if the program were out of reach; now the force and the file it came from too."""
    prog = tmp_path / "p.nc"
    prog.write_bytes(b"".join(PROGRAM.read_bytes().splitlines(keepends=True)[:16]))  # feed: lines 15, 16
    forces = tmp_path / "f.csv"
    forces.write_text("line,fx,fy\n15,0,-490.5\n16,0,10000000\n")
    out = tmp_path / "o.nc"
    code, _, err = _run_3prr(prog, out, monkeypatch, capsys, force=("--force-file", forces))
    _one_line(code, err, "p.nc: line 16:", "under F = (0, 1e+07, 0) N", "unreachable", "from " + str(forces))
    assert not out.exists()


def test_a_force_too_large_for_the_model_is_refused_not_a_hang():
    """1e5 N across a cut of the 3PRR (a deflection of 90 mm): the commanded point's fixed point never
    converged and every piece was halved again, 32768 pieces after 23 s (a hang under the fuzz
    harness's 20 s limit); now one line naming the line, the force and its file, in seconds."""
    from helpers.fuzz import run_case
    from helpers.fuzz_machining import compensate_case

    prog = b"".join(PROGRAM.read_bytes().splitlines(keepends=True)[:16])  # feed moves: lines 15, 16
    forces = b"line,fx,fy\n15,0,-490.5\n16,0,100000\n"
    case = compensate_case(
        {"p.nc": prog, "f.csv": forces},
        "3prr",
        "p.nc",
        "--place",
        "380,200",
        "--force-file",
        "{dir}/f.csv",
        blamed="f.csv",
    )
    o = run_case(case)
    assert o.kind == "clear" and o.seconds < 10.0, (o.kind, o.seconds, o.stderr)
    _one_line(o.code, o.stderr, "p.nc: line 16:", "no commanded point", "under F = (0, 100000, 0) N", "f.csv")


def test_an_arc_whose_ends_share_an_in_plane_coordinate_writes_it():
    """A G18 arc from z 0 to z 0 (its line names X and Y, the helix's normal axis, not Z): its pieces
    did not write Z, so the machine cut a chord 3.4 mm (the arc's sagitta) from the arc. Found by the
    long fuzz profile (own_inch_r_planes.nc with a G18 line inserted); the output now passes the
    independent re-check."""
    from helpers.fuzz import run_case
    from helpers.fuzz_machining import compensate_case

    lines = (DATA / "own_inch_r_planes.nc").read_text().splitlines(keepends=True)
    text = "".join([*lines[:3], "G18\n", *lines[3:]]).encode()
    case = compensate_case(
        {"p.nc": text}, "3prr", "p.nc", "--place", "380,200", "--force-n", "0,-490.5", blamed="p.nc"
    )
    o = run_case(case)
    assert o.kind == "ok", (o.kind, o.detail, o.stderr)


def test_a_deflection_too_large_for_a_stiffness_model_is_warned(tmp_path, monkeypatch, capsys):
    """A force that deflects the 3PRR by millimetres (a kN typed for N, a model's stiffness off by
    ten) was compensated with exit 0 and no word: now one warning naming the program and the
    deflection (exit 1, the program still written); the study's 50 kgf stays silent."""
    prog = tmp_path / "p.nc"
    prog.write_bytes(b"".join(PROGRAM.read_bytes().splitlines(keepends=True)[:16]))
    study = {"h": 800.0, "L": 250.0, "EA": 7e6, "kj": 525.0, "kb": 9800.0}
    P = output_samples(toolpath_from_moves(read_program(prog)[0].moves))[2][:, :2] + [380.0, 200.0]
    for fy, warned in ((-490.5, False), (-4000.0, True)):
        out = tmp_path / f"out{-fy:g}.nc"
        code, _, err = _run_3prr(
            prog, out, monkeypatch, capsys, "--no-figures", force=("--force-n", f"0,{fy}")
        )
        before = np.linalg.norm(truss_3prr(P, [0.0, fy], **study), axis=1).max()  # independent
        assert out.exists() and (before > 4.0) == warned, (before, err)
        if not warned:
            assert code == 0 and "warning" not in err, err
            continue
        assert code == 1, err
        lines = [ln for ln in err.splitlines() if ln.startswith("warning:")]
        assert len(lines) == 1 and "p.nc" in lines[0] and "stiffness model" in lines[0], err
        shown = float(lines[0].split("by up to ")[1].split(" mm")[0])
        assert shown == pytest.approx(before, rel=0.02), (shown, before)


@pytest.mark.parametrize(
    ("name", "text", "place", "force", "needles"),
    [
        ("p.nc", "G21 G90\nG0 X0 Y0\nG1 X1_5 F100\nG1 Y5\n", "380,200", "0,-490", ["p.nc", "line 3", "'_5"]),
        (
            "p.csv",
            "x,y\n0,0\n1_0,0\n10,10\n",
            "380,200",
            "0,-490",
            ["p.csv", "line 3", "'1_0' is not a number"],
        ),
        (
            "p.csv",
            "x,y\n0,0\n١٠,0\n10,10\n",
            "380,200",
            "0,-490",
            ["p.csv", "line 3", "'x'", "is not a number"],
        ),
        ("p.csv", "x,y\n0,0\n10,0\n", "380,200", "0,-49_0", ["--force-n", "'0,-49_0'"]),
        ("p.csv", "x,y\n0,0\n10,0\n", "38_0,200", "0,-490", ["--place", "'38_0,200'"]),
    ],
)
def test_a_number_with_an_underscore_is_refused(
    tmp_path, monkeypatch, capsys, name, text, place, force, needles
):
    """Python's float reads '1_5' as 15 and '١٠' (Arabic-Indic digits) as 10; a controller refuses
    them and so does compensate, naming the file and line (or the option). The CSV of points was
    read with x = 10 and compensated (exit 0), as were --force-n 0,-49_0 (-490 N) and --place 38_0."""
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    out = tmp_path / ("o" + p.suffix)
    code, _, err = _run_3prr(p, out, monkeypatch, capsys, place=place, force=("--force-n", force))
    _one_line(code, err, *needles)
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--q-seed-deg", "0,0"], ["--q-seed-deg", "expected 6 joint angles", "joint_6", "got 2"]),
        (["--q-seed-deg", "400,0,0,0,0,0"], ["--q-seed-deg", "joint_1 at 400 deg beyond its limits"]),
        (["--q-seed-deg", "nan"], ["--q-seed-deg", "1 to 12 comma-separated numbers"]),
        (["--param", "k_theta=inf"], ["--param", "every joint of stiffmap_arm6 is rigid"]),
    ],
)
def test_an_arm_seed_or_springs_it_cannot_take_are_refused(tmp_path, monkeypatch, capsys, args, needles):
    """The seed's length was refused naming the URDF file (not the option); a seed beyond the joint
    limits (400 deg) was taken, the program's first point then refused as unreachable ('joint_1 at
    356 deg'); an arm of rigid joints had its first point called singular (conditioning 0)."""
    out = tmp_path / "o.nc"
    argv = ["compensate", "urdf", "arm6", "--path", PROGRAM, "--out", out, "-q", "--place", "480,-30,380"]
    code, _, err = run_in_process([*argv, "--force-n", "20,-15,10", *args], monkeypatch, capsys)
    _one_line(code, err, *needles)
    assert list(tmp_path.iterdir()) == []


#: A program in the plane of arm6's first joint through its base (y = 0 when placed at y = 0): the
#: five joints to link_5 can hold link_5's orientation there (off that plane they cannot).
IN_PLANE = "G21 G90\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X20\nG1 Z10\n"


def test_a_shorter_chain_of_the_arm_takes_its_seed_and_springs(tmp_path, monkeypatch, capsys):
    """``--tip link_5`` on arm6 (five joints): the arm's six-joint seed was refused ('q_seed_deg: 6
    joint values; the robot has 5 joints') though no --q-seed-deg was given. Now the chain takes the
    arm's seed and springs of its five joints, and the written program, deflected by an independent
    solver (central-difference Jacobian, C = J K^-1 J^T on the chain to link_5, the orientation of
    link_5 at the seed held), lies within the tolerance (1 um) of the programmed path."""
    prog = tmp_path / "p.ngc"
    prog.write_text(IN_PLANE)
    out = tmp_path / "o.ngc"
    place, force = np.array([400.0, 0.0, 300.0]), np.array([0.0, 0.0, -50.0])
    argv = ["compensate", "urdf", "arm6", "--tip", "link_5", "--path", prog, "--out", out, "-q", "--json"]
    argv += ["--place", "400,0,300", "--force-n", "0,0,-50"]
    code, text, err = run_in_process(argv, monkeypatch, capsys)
    assert code == 0, err
    assert json.loads(text)["deflection_before_um"]["worst"] > 100.0  # something worth checking
    chain = Chain.from_urdf(arm6.URDF, "link_5")
    seed = np.radians(arm6.Q_SEED_DEG[:5])
    done, _ = read_program(out)
    _, _, C = output_samples(toolpath_from_moves(done.moves), per_mm=2.0)
    d, _ = arm_deflection(
        chain, arm6.K_THETA[:5], chain.forward(seed)[1], C + place, np.tile(force, (len(C), 1)), seed
    )
    programmed = toolpath_from_moves(read_program(prog)[0].moves)
    assert np.max(distance_to_path(programmed, C + d)) <= 1e-3 + 1e-9
    code, _, err = run_in_process([*argv, "--q-seed-deg", "0,40,-10,0,60,0"], monkeypatch, capsys)
    _one_line(code, err, "--q-seed-deg", "expected 5 joint angles", "joint_5", "got 6")


@pytest.mark.parametrize("spin", [[], ["--free-tool-spin"]])
def test_a_placement_far_out_of_the_arms_reach_is_refused_at_once(tmp_path, monkeypatch, capsys, spin):
    """--place 1e6,0,0 on arm6: the inverse kinematics was tried along the program (2 s) and, with
    --free-tool-spin, at every spin (6 s, 13 s on a busy machine) before 'no smooth choice of spins
    keeps every point reachable'. Now one line names the program's first line and the reach (1264
    mm from joint_1's origin: test_models_chain), before any search, within a generous 3 s here."""
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X20\nG1 Y20\n")
    out = tmp_path / "o.ngc"
    argv = ["compensate", "urdf", "arm6", "--path", prog, "--out", out, "--place", "1e6,0,0"]
    where = ["p.ngc: line 2:", "(1e+06, 0, 0) mm (base frame)", "out of the arm's reach", " 1264 mm"]
    t0 = time.perf_counter()
    code, _, err = run_in_process([*argv, "--force-n", "0,0,-50", *spin], monkeypatch, capsys)
    assert time.perf_counter() - t0 < 3.0
    _one_line(code, err, *where)
    assert not out.exists()


def _campaign(tmp_path, seed: str, *sql) -> Path:
    """A measured test-bed campaign (helpers.fuzz_safety.measured_seed: the sensor seed's 3PRR with
    its fit of kj) in ``tmp_path/c``, its stiffmap.db edited by ``sql``."""
    files = campaign_files(seed)
    if sql:
        files["c/stiffmap.db"] = edited_db(files["c/stiffmap.db"], *sql)
    for name, data in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(data)
    return tmp_path / "c"


@pytest.mark.parametrize(
    ("sql", "needles"),
    [
        (("UPDATE model_fit SET cov = '[[-1]]'",), ["negative variance"]),
        (("UPDATE model_fit SET cov = '[[1e308]]'",), ["standard error of kj over a million times"]),
        (("UPDATE model_fit SET params = '{\"kj\": -5}'",), ["fitted parameters", "kj must be a positive"]),
        (("UPDATE model_fit SET params = '{\"nope\": 5}'",), ["fitted parameters", "unknown 3PRR parameter"]),
        (("UPDATE model_fit SET status = 'half'",), ["model fit failed: its status is 'half'"]),
    ],
)
def test_a_damaged_fit_is_refused_naming_the_database(tmp_path, monkeypatch, capsys, sql, needles):
    """Found by the --from-campaign fuzz class: a negative variance gave a 95 % band of 0 um (exit 0),
    a variance of 1e308 an internal error (exit 3), fitted parameters the robot refuses were blamed on
    campaign.toml, and a status neither ok nor failed said 'failed: None'."""
    camp = _campaign(tmp_path, "sensor", sql)
    prog = tmp_path / "p.ngc"
    prog.write_bytes(b"G21 G90 G17\nG0 X0 Y0 Z0\nG1 X10 Y0 F100\n")
    out = tmp_path / "o.ngc"
    argv = ["compensate", "--from-campaign", camp, "--path", prog, "--out", out, "-q", "--no-figures"]
    code, _, err = run_in_process([*argv, "--place", "400,300", "--force-n", "100,-50"], monkeypatch, capsys)
    _one_line(code, err, "stiffmap.db", *needles)
    assert not out.exists()


def test_a_campaign_without_a_model_is_refused_naming_it(tmp_path, monkeypatch, capsys):
    """A campaign whose robot.model is "none" was told to run 'stiffmap run' again (no fit in its
    database), which fits nothing either."""
    camp = _campaign(tmp_path, "sensor")
    toml = camp / "campaign.toml"
    text = toml.read_text()
    robot = text[text.index("[robot]") : text.index("\n[", text.index("[robot]"))]
    toml.write_text(text.replace(robot, '[robot]\nmodel = "none"\n'))
    prog = tmp_path / "p.ngc"
    prog.write_bytes(b"G21 G90 G17\nG0 X0 Y0 Z0\nG1 X10 Y0 F100\n")
    argv = ["compensate", "--from-campaign", camp, "--path", prog, "--out", tmp_path / "o.ngc", "-q"]
    code, _, err = run_in_process([*argv, "--place", "400,300", "--force-n", "100,-50"], monkeypatch, capsys)
    _one_line(code, err, "campaign.toml", 'robot.model = "none"', "give the robot KIND")


def test_a_tool_orientation_the_arm_cannot_hold_without_spin_is_summarised(tmp_path, monkeypatch, capsys):
    """Found by the arm's fuzz class: with --free-tool-spin and a tool orientation (1e9 deg of roll)
    that no knot of the program reaches without turning the tool, the summary's worst deflection at
    the fixed spin was the max of NaNs: a RuntimeWarning (exit 3 under the fuzz harness, exit 1 with
    'warning: All-NaN slice encountered' from the command line). It is null ('unreachable')."""
    out = tmp_path / "o.nc"
    argv = ["compensate", "urdf", "arm6", "--path", PROGRAM, "--out", out, "-q", "--place", "480,-30,380"]
    argv += [
        "--force-n",
        "20,-15,10",
        "--free-tool-spin",
        "--tool-rpy-deg",
        "1e9,0,0",
        "--json",
        "--no-figures",
    ]
    code, stdout, err = run_in_process(argv, monkeypatch, capsys)
    assert code == 0 and "warning" not in err, err
    spin = json.loads(stdout)["spin"]
    assert spin["worst_fixed_um"] is None and 100.0 < spin["worst_chosen_um"] < 2000.0, spin


def test_a_deflection_too_large_names_the_force_file_it_is_from(tmp_path, monkeypatch, capsys):
    """Found by the force file's fuzz class (3 of 150 inputs): a force file of kN typed for N was
    warned naming only the program; the force is the file's, so the warning names it too."""
    prog = tmp_path / "p.nc"
    prog.write_bytes(b"".join(PROGRAM.read_bytes().splitlines(keepends=True)[:16]))
    forces = tmp_path / "f.csv"
    forces.write_text(_FORCES.replace("-490.5", "-4000"))
    out = tmp_path / "o.nc"
    code, _, err = _run_3prr(prog, out, monkeypatch, capsys, "--no-figures", force=("--force-file", forces))
    lines = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    assert code == 1 and len(lines) == 1 and "p.nc" in lines[0] and "from " + str(forces) in lines[0], err
