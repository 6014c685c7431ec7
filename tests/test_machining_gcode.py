"""The G-code reader and writer: moves and arcs computed by hand, lines kept verbatim, refusals named.

Hand computations: the cncjs inch circle (MIT, tests/data/gcode/README.md) is four quarter
arcs of radius 0.5 in = 12.7 mm about the origin; an R-format arc from (0, 0) to (10, 10)
with R 10 counter-clockwise has its centre at (0, 10) (the left of the chord for G3 and
R > 0), with R -10 at (10, 0); G18 arcs turn in the (Z, X) plane and G19 in (Y, Z), counter-
clockwise seen from +Y and +X (RS274/NGC).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stiffmap.errors import InputError
from stiffmap.machining.gcode import (
    ARC_CW,
    LINE,
    RAPID,
    GcodeError,
    Piece,
    parse_program,
    render_program,
)
from stiffmap.machining.io import read_force_file, read_program
from stiffmap.machining.path import toolpath_from_moves

DATA = Path(__file__).parent / "data" / "gcode"


def test_inch_circle_arcs_by_hand():
    prog, text = read_program(DATA / "cncjs_circle-inch.gcode")
    assert text.text.count("\r\n") == 11  # CRLF kept for writing back
    arcs = [m for m in prog.moves if m.kind == ARC_CW]
    assert len(arcs) == 4
    for m in arcs:
        np.testing.assert_allclose(m.centre[:2], [0.0, 0.0], atol=1e-12)
        assert math.hypot(*m.start[:2]) == pytest.approx(12.7, abs=1e-12)
        assert m.inch
    path = toolpath_from_moves(prog.moves)
    i = prog.move_at_line[6]
    assert path.sweep[i] == pytest.approx(-math.pi / 2)  # clockwise quarter turn
    assert path.length()[i] == pytest.approx(12.7 * math.pi / 2, rel=1e-12)
    np.testing.assert_allclose(
        path.point([i], [0.5])[0, :2], 12.7 * np.array([-1, 1]) / math.sqrt(2), atol=1e-12
    )


def test_r_format_centres_and_planes():
    p = parse_program("G21 G90\nG0 X0 Y0 Z0\nG3 X10 Y10 R10\nG0 X0 Y0\nG3 X10 Y10 R-10\n")
    a, b = p.moves[1], p.moves[3]
    np.testing.assert_allclose(a.centre[:2], [0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(b.centre[:2], [10.0, 0.0], atol=1e-12)
    path = toolpath_from_moves(p.moves)
    assert path.sweep[1] == pytest.approx(math.pi / 2)
    assert path.sweep[3] == pytest.approx(3 * math.pi / 2)  # R < 0: the long way round
    q = parse_program("G0 X0 Y0 Z0\nG18 G2 X20 Z0 I10 K0\nG19 G3 Y10 Z10 J0 K10\n")
    path = toolpath_from_moves(q.moves)
    # G2 in (Z, X), clockwise seen from +Y (Z x X = Y): from x 0 to x 20 about x 10 through z = -10
    mid = path.point([1], [0.5])[0]
    np.testing.assert_allclose(mid, [10.0, 0.0, -10.0], atol=1e-12)
    mid = path.point([2], [0.5])[0]  # G3 in (Y, Z) about (y 0, z 10), quarter turn from z 0 to y 10
    np.testing.assert_allclose(mid, [20.0, 10 / math.sqrt(2), 10 - 10 / math.sqrt(2)], atol=1e-12)


def test_lower_case_no_spaces_incremental_and_modal_motion():
    p = parse_program("g21g91\ng0x1y2z3\ng1x1\ny-1f100\ng90x0y0\n")
    ends = [m.end.tolist() for m in p.moves]
    assert ends == [[1, 2, 3], [2, 2, 3], [2, 1, 3], [0, 0, 3]]
    assert [m.kind for m in p.moves] == [RAPID, LINE, LINE, LINE]
    assert all(m.lower and (m.compact or len(m.spans) == 1) for m in p.moves[:2])


def test_unchanged_moves_write_the_same_text():
    for name in ("cncjs_toolpath.nc", "own_cam_mm.nc", "own_inch_r_planes.nc", "cncjs_circle-inch.gcode"):
        prog, text = read_program(DATA / name)
        assert render_program(prog, {}, {}) == text.text


def test_rewritten_lines_keep_words_comments_and_style():
    p = parse_program("N5 g1x10.y2.f300(cut) ; ok\nN6 X20.\n")
    out = render_program(p, {0: [Piece(LINE, np.array([10.5, 2.25, 0.0]))]}, {0: (0, 1, 2)})
    first = out.splitlines()[0]
    assert first == "N5 g1x10.5y2.25z0.f300(cut) ; ok"
    # after an inserted G1 line, the next line that relied on the modal G2 gets its G2 back
    p = parse_program("G0 X0 Y0 Z0\nG2 X10 Y0 I5 J0 F100\nX0 Y0 I-5 J0\n")
    outs = {
        1: [
            Piece(ARC_CW, np.array([10.0, 0.0, 0.0]), np.array([5.0, 0.0, 0.0])),
            Piece(LINE, np.array([9.0, 0.0, 0.0])),
        ]
    }
    lines = render_program(p, outs, {1: (0, 1)}).splitlines()
    assert lines[2] == "G1 X9. Y0."
    assert lines[3] == "G2 X0 Y0 I-5 J0"  # kept verbatim, its motion word restored
    outs[2] = [Piece(ARC_CW, np.array([0.0, 0.0, 0.0]), np.array([4.5, 0.0, 0.0]))]
    lines = render_program(p, outs, {1: (0, 1), 2: (0, 1)}).splitlines()
    assert lines[3] == "G2 X0. Y0. I-4.5 J0."  # the motion word restored


def test_motion_mode_set_on_a_line_of_its_own_is_not_written_again():
    # a hand-written program (the style of a teaching example: ``G00;`` alone, then axis words;
    # ``G01 F5.;`` alone, then a plunge): unchanged moves are written back unchanged, without a
    # motion word added in front of them
    text = "G90 G17;\nG00;\nX0. Y0. Z0.;\nG91;\nZ0.15;\nG01 F5.;\nZ-0.3;\nX0.25 Y-0.25;\n"
    p = parse_program(text)
    assert [m.motion_before for m in p.moves] == [0, 0, 1, 1]
    assert render_program(p, {}, {}) == text


def test_incremental_lines_after_a_compensated_cut_start_where_the_tool_is():
    # G91: a cut compensated to end 0.5 mm off its programmed end; the retract names only Z, so
    # X and Y stay where the cut left them, and the rapid into the next cut takes its increments
    # from there to that cut's compensated start (20, 0.3, 5)
    text = "G21 G91\nG0 X0 Y0 Z0\nG1 X10 F100\nG0 Z5\nG0 X10\nG1 Z-5\n"
    p = parse_program(text)
    outs = {1: [Piece(LINE, np.array([10.0, 0.5, 0.0]))], 3: [Piece(RAPID, np.array([20.0, 0.3, 5.0]))]}
    lines = render_program(p, outs, {1: (0, 1, 2), 3: (0, 1, 2)}).splitlines()
    assert lines[2] == "G1 X10. Y0.5 Z0. F100"
    assert lines[3] == "G0 Z5"  # verbatim: its Z increment starts where the program's does
    assert lines[4] == "G0 X10. Y-0.2 Z0."
    q = parse_program("\n".join(lines))
    np.testing.assert_allclose(q.moves[3].end, [20.0, 0.3, 5.0], atol=1e-12)


def test_lines_after_the_program_end_are_kept_and_not_read():
    # M2/M30 end a program (RS274/NGC: lines after them are not run), so does the second '%' of
    # a program delimited by '%' lines; what follows (notes, a tool list, junk) is kept verbatim
    for text in (
        "G21\nG0 X0 Y0 Z0\nG1 X5 F100\nM30\nT1 D=6 (Fraeser\nG1 X#1\n",
        "%\nG21\nG0 X0 Y0 Z0\nG1 X5 F100\n%\nG81 X1 Y1 Z-1 R1\n",
        "g0 x0 y0 z0\ng1 x5 f100\nm02\nblah\n",
    ):
        p = parse_program(text)
        assert [m.end[0] for m in p.moves] == [0.0, 5.0]
        assert render_program(p, {}, {}) == text
    with pytest.raises(GcodeError, match="line 2: cannot read 'blah'"):
        parse_program("G0 X0 Y0 Z0\nblah\nM30\n")


def test_spaces_inside_words_and_colon_program_numbers():
    # RS274/NGC ignores spaces: "G0 Z 10", "G2 I -45" (LinuxCNC's hk_ba20_testmill.ngc) and
    # "X - 5"; ":1000" is an ISO program number (Fanuc), like "O1000"
    p = parse_program(":1000\nG21 G90\nG0 X0 Y 0 Z 10\nG1 X - 5 Z -1 F100\nG2 I -45\n")
    np.testing.assert_allclose([m.end for m in p.moves], [[0, 0, 10], [-5, 0, -1], [-5, 0, -1]])
    np.testing.assert_allclose(p.moves[2].centre, [-50.0, 0.0, -1.0])


def test_axis_words_after_g80_are_refused_or_passed_through():
    # "G80 X10 (do nothing)", as in the webgcode simulator's example program: RS274/NGC refuses
    # axis words with no motion mode, Fanuc moves in the last G0/G1: refused, naming the line;
    # with pass_through the line is kept and X is unknown until the program gives it again
    text = "G21 G90\nG0 X0 Y0 Z0\nG1 X5 F100\nG80 X10 (do nothing)\nG0 X30 Y30 Z30\nG1 X40\n"
    with pytest.raises(GcodeError, match="line 4: axis words with no motion mode in force"):
        parse_program(text)
    p = parse_program(text, pass_through=True)
    assert [w.split(":")[0] for w in p.warnings] == ["line 4"]
    assert p.moves[2].known == (True, True, True) and p.moves[2].end.tolist() == [30.0, 30.0, 30.0]
    assert render_program(p, {}, {}) == text
    with pytest.raises(GcodeError, match="line 5: an incremental X move from an unknown X"):
        parse_program(text.replace("G0 X30 Y30 Z30", "G91 G0 X30 Y30 Z30"), pass_through=True)


def test_work_offset_chosen_after_g53_before_the_first_move():
    # cncjs's linear.nc (MIT; a Fusion-style preamble): G53 Z0. moves in machine coordinates,
    # then G55 chooses the work offset before any move in the program's frame: accepted. A change
    # after a move in the program's frame is still refused.
    prog, _ = read_program(DATA / "cncjs_linear.nc")
    assert [m.line for m in prog.moves] == [10, 11, 12, 13] and prog.moves[-1].feed
    np.testing.assert_allclose(prog.moves[-1].end, [1.1185 * 25.4, 0.5562 * 25.4, -0.0365 * 25.4])
    with pytest.raises(GcodeError, match="line 3: G55 changes the work offset"):
        parse_program("G0 X0 Y0 Z0\nG53 G0 Z0\nG55\nG0 X1 Y1 Z1\n")


def test_arc_tolerances_are_linuxcncs():
    # CAM output rounds centres and end points (4 decimals in inch): an arc whose end radius
    # differs by 0.0001 in (2.5 um, 1 %) is cut by LinuxCNC (CENTER_ARC_RADIUS_TOLERANCE_INCH
    # 0.002 sqrt 2 in) and read here, as the spiral LinuxCNC cuts; 0.01 mm in a mm program too
    p = parse_program("G20\nG0 X0 Y0 Z0\nG1 X0.0100 F10\nG3 X0.0001 Y0.0101 I-0.0100 J0\n")
    path = toolpath_from_moves(p.moves)
    assert path.r0[2] == pytest.approx(0.254) and path.r1[2] - path.r0[2] == pytest.approx(0.00254, rel=0.02)
    parse_program("G21\nG0 X0 Y0 Z0\nG3 X-5 Y5.01 I-5 J0\n")
    with pytest.raises(GcodeError, match="line 3: arc radius"):  # 0.05 mm and 1 %: beyond both
        parse_program("G21\nG0 X0 Y0 Z0\nG3 X-5 Y5.05 I-5 J0\n")
    # an R-format half circle whose R was rounded down by 0.5 um (LinuxCNC: RADIUS_TOLERANCE
    # 0.00005 in) is a half circle about the chord's middle
    q = parse_program("G21\nG0 X0 Y0 Z0\nG2 X10.001 Y0 R5\n")
    np.testing.assert_allclose(q.moves[1].centre, [5.0005, 0.0, 0.0], atol=1e-12)
    with pytest.raises(GcodeError, match="less than half the chord"):
        parse_program("G21\nG0 X0 Y0 Z0\nG2 X10.01 Y0 R5\n")


def test_carriage_return_line_endings_are_kept():
    # a program saved with CR alone (classic Mac OS, some old DNC tools) is written back so
    for nl in ("\r", "\r\n", "\n"):
        text = nl.join(["%", "G21 G90", "G0 X0 Y0 Z0", "G1 X5 F100", "%"]) + nl
        p = parse_program(text)
        assert [m.end[0] for m in p.moves] == [0.0, 5.0]
        out = render_program(p, {1: [Piece(LINE, np.array([5.25, 0.0, 0.0]))]}, {1: (0, 1)})
        assert out == text.replace("X5 F100", "X5.25 Y0. F100")


def test_g28_leaves_z_unknown_until_given():
    p = parse_program("G21 G90\nG0 X0 Y0 Z5\nG28 G91 Z0.\nG90\nG0 X10 Y10\nG43 Z15. H1\n")
    assert p.moves[1].known == (True, True, False)
    assert p.moves[2].known == (True, True, True)


@pytest.mark.parametrize(
    ("text", "line", "what"),
    [
        ("G0 X0 Y0\no100 sub\n", 2, "O-words"),
        ("G0 X0\nG1 X#1\n", 2, "'#' parameters"),
        ("G0 X0\nG1 X[1+2]\n", 2, "expressions"),
        ("G0 X0 Y0 Z5\nG81 X1 Y1 Z-2 R1 F50\n", 2, "canned cycle G81"),
        ("G0 X0 Y0\nG41 D1 G1 X5\n", 2, "cutter-radius compensation"),
        ("G93\nG1 X1 F2\n", 1, "inverse-time"),
        ("G0 X0\nG92 X0\n", 2, "coordinate offset"),
        ("G0 X0 Y0\nG55 G0 X1\n", 2, "work offset"),
        ("G0 X0 Y0\nG2 X1 Y1\n", 2, "arc without its centre"),
        ("G0 X0 Y0\nG2 X10 Y0 I1 J0\n", 2, "radius"),
        ("G0 X0 Y0\nG2 X30 Y0 R10\n", 2, "less than half the chord"),
        ("G0 X0 Y0\nG1 X1 (open\n", 2, "not closed"),
        ("G0 X0 Y0\nG1 X1 E5\n", 2, "cannot read"),
        ("G0 X0 Y0\nG5.1 X1 I1 J1\n", 2, "G5.1 is not supported"),
        ("G0 X0 Y0\nM98 P100\n", 2, "subprogram"),
        # what is not G-code, seen in public programs (grbl senders, RepRap hosts, LinuxCNC)
        ("$I  ; View build info\nG0 X0\n", 1, "'$' starts a grbl system command"),
        ("N3 T0*57\n", 1, "RepRap line checksum"),
        ("G0 X1.5 Y0 Z0\nG91 G81 R.1 Z-.5 ^60 L6 F10\n", 2, "polar coordinates"),
        ("G0 X0 Y0\nG1 X1,5 F100\n", 2, "decimal comma"),
        ("G0 X0 Y0\nG1 X1 E5\n", 2, "extruder word"),
    ],
)
def test_refusals_name_the_line(text, line, what):
    with pytest.raises(GcodeError) as e:
        parse_program(text, "prog.nc")
    msg = str(e.value)
    assert msg.startswith(f"prog.nc: line {line}: ") and what in msg
    assert "\n" not in msg


def test_pass_through_keeps_lines_and_warns():
    text = "G21 G90\nG0 X0 Y0 Z5\nG81 X1 Y1 Z-2 R1 F50\nG80\nG41 D1\nG1 X5\nG40\nG0 X0 Y0 Z5\n"
    p = parse_program(text, pass_through=True)
    assert [w.split(":")[0] for w in p.warnings] == ["line 3", "line 5", "line 6"]
    assert render_program(p, {}, {}) == text
    assert p.moves[-1].known == (True, True, True)


def test_force_file_rows_must_match_the_feed_moves(tmp_path):
    f = tmp_path / "forces.csv"
    f.write_text("line,fx,fy\n3,10,0\n4,0,10\n")
    F = read_force_file(f, np.array([3, 4]))
    np.testing.assert_array_equal(F, [[10, 0, 0], [0, 10, 0]])
    with pytest.raises(InputError, match=r"forces.csv: 2 force row\(s\), but the program has 3 feed move"):
        read_force_file(f, np.array([3, 4, 5]))
    with pytest.raises(
        InputError, match=r"line 3, column 'line': 4, but feed move 2 of the program is on line 6"
    ):
        read_force_file(f, np.array([3, 6]))


def test_latin1_comments_are_written_back_byte_for_byte(tmp_path):
    raw = "G21 G90 (Fräser Ø6)\nG0 X0 Y0 Z5\nG1 Z0 F100\n".encode("latin-1")
    f = tmp_path / "p.nc"
    f.write_bytes(raw)
    prog, text = read_program(f)
    assert text.encoding == "latin-1"
    assert render_program(prog, {}, {}).encode(text.encoding) == raw


_WORDS = st.sampled_from(
    [
        "G0",
        "G1",
        "G2",
        "G3",
        "G17",
        "G18",
        "G91",
        "G90",
        "X1",
        "Y-2.5",
        "Z.5",
        "I1",
        "J0",
        "R3",
        "F100",
        "M3",
        "#1",
        "[",
        "(c)",
        ";x",
        "O1",
        "N10",
        "G81",
        "T1",
        "Q",
        "%",
        "/",
        "g1x1",
    ]
)


@pytest.mark.fuzz
@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(_WORDS, max_size=6).map(" ".join), max_size=8))
def test_malformed_programs_raise_input_errors_only(lines):
    """Any jumble of words: a parsed program or a one-line InputError, never another exception."""
    text = "\n".join(lines)
    for passing in (False, True):
        try:
            p = parse_program(text, "x.nc", pass_through=passing)
        except InputError as e:
            assert "\n" not in str(e)
            continue
        assert render_program(p, {}, {}) == "\n".join(text.splitlines()) + (
            "\n" if text.endswith("\n") else ""
        )


def test_public_r_format_program_without_centre_is_refused_at_its_line():
    """cncjs's arc-r.nc writes 'X0Y20' in G02 mode without I/J/R: an arc whose centre no word gives."""
    with pytest.raises(GcodeError, match=r"cncjs_arc-r.nc: line 3: arc without its centre"):
        read_program(DATA / "cncjs_arc-r.nc")
