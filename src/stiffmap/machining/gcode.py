"""RS274/NGC G-code: the moves of a machining program, and the program written back.

:func:`parse_program` reads the text of a program into a :class:`Program`: every line kept
verbatim, and every move (G0, G1, G2, G3) with its start and end in mm in the program's
frame, its arc (centre, plane, direction) and the spans of its coordinate words, so that
:func:`render_program` can write the same program with new coordinates for the moves and
every other line unchanged, in place.

What is understood (docs/machining.md): G0/G1/G2/G3 with I/J/K (incremental, or absolute
under G90.1) or R, helical arcs, G17/G18/G19, G20/G21 (positions in mm inside, the output
in the input's units), G90/G91, modal motion (a line of axis words moves in the last
motion mode), line numbers, F/S/T/M/H/D words, comments ``( )`` and ``;``, lower case,
no spaces between words, G4, G28/G30 and G53 (kept verbatim; the axes they move are then
unknown until the program gives them again), G40, G43/G49, G54-G59 (one work offset),
G61/G64, G80, G94/G95, G98/G99. Rotary and other axes (A, B, C, U, V, W) stay in their
lines unchanged.

Spaces are ignored inside words as RS274/NGC says (``G0 Z 10``, ``X - 5``). A line holding
only a program number (``O1001``, ``:1001``, as Fanuc posts write) is kept. M2/M30, or the
second ``%`` of a program that opens with one, end the program: the lines after them are
kept verbatim and not read (a controller never runs them). What
cannot be compensated safely is refused with its line number (a :class:`GcodeError`):
O-words (subprograms, loops, conditions), ``#`` parameters, ``[expressions]``,
canned cycles (G73-G89), cutter-radius compensation on (G41/G42), inverse-time feed (G93),
axis words with no motion mode in force (``G80 X10``),
coordinate offsets (G10, G52, G92), a change of work offset after the first move, and
every other G-code; what is not G-code (grbl's ``$`` commands, RepRap checksums ``*57``,
polar ``^``, decimal commas, extruder ``E`` words) is named as such. With
``pass_through=True`` such a line is kept unchanged and named in :attr:`Program.warnings`;
the axes it names are then unknown, and the lines between
G41/G42 and G40 (or G93 and G94) are passed through too.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = [
    "GcodeError",
    "Move",
    "Program",
    "Piece",
    "parse_program",
    "render_program",
    "MM_PER_INCH",
    "written_resolution_mm",
    "RAPID",
    "LINE",
    "ARC_CW",
    "ARC_CCW",
]

MM_PER_INCH = 25.4
#: Motion kinds of :attr:`Move.kind`.
RAPID, LINE, ARC_CW, ARC_CCW = 0, 1, 2, 3
#: In-plane axes (a, b) and normal axis n of G17, G18, G19 (indices into x, y, z):
#: G2 turns clockwise in (a, b) seen from +n.
PLANE_AXES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
#: Arc centre words of each axis.
_CENTRE_WORD = {0: "I", 1: "J", 2: "K"}
#: An arc's start and end radii may differ by this much (mm; in an inch program by
#: ARC_RADIUS_TOL_INCH) or by this fraction of the radius, as LinuxCNC allows (its
#: CENTER_ARC_RADIUS_TOLERANCE and SPIRAL_RELATIVE_TOLERANCE, src/emc/rs274ngc/interp_internal.hh:
#: "any valid arc where the endpoints and/or centerpoint got rounded or truncated to 0.001 inch
#: or 0.01 mm precision would be accepted"); between them the path is a spiral, as LinuxCNC cuts it.
ARC_RADIUS_TOL_MM = 2 * 0.01 * math.sqrt(2)
ARC_RADIUS_TOL_INCH = 2 * 0.001 * math.sqrt(2)
ARC_RADIUS_RTOL = 1e-3
#: An R-format arc's R may be this much (mm; inch: R_TOL_INCH) shorter than half its chord (the
#: arc is then a half circle): LinuxCNC's RADIUS_TOLERANCE, for R rounded in the program.
R_TOL_MM = 0.00005 * 25.4
R_TOL_INCH = 0.00005

#: The largest number a word may hold (a coordinate of 1e9 mm is already beyond any machine; a
#: number of hundreds of digits is infinite in floating point).
MAX_WORD_VALUE = 1e9
#: A word: a letter and a number; RS274/NGC ignores spaces, so ``X -5`` and ``X - 5`` read as ``X-5``.
_WORD = re.compile(r"([A-Za-z])\s*([+-]?)\s*(\d+\.?\d*|\.\d+)")
_LETTERS = set("ABCDFGHIJKLMNPQRSTUVWXYZ")
_PROGRAM_NUMBER = re.compile(r"\s*[Oo:]\s*\d+\s*")
_KEEP_G = {4, 40, 43, 43.1, 49, 54, 55, 56, 57, 58, 59, 59.1, 59.2, 59.3, 61, 61.1, 64, 69, 80, 94, 95}
_KEEP_G |= {96, 97, 98, 99, 17, 18, 19, 20, 21, 90, 91, 90.1, 91.1, 0, 1, 2, 3, 28, 30, 28.1, 30.1, 53}
_REFUSED_G = {
    41: "cutter-radius compensation (G41) moves the path by the tool radius the controller holds",
    42: "cutter-radius compensation (G42) moves the path by the tool radius the controller holds",
    41.1: "dynamic cutter-radius compensation (G41.1)",
    42.1: "dynamic cutter-radius compensation (G42.1)",
    93: "inverse-time feed (G93): the feed words would not survive subdividing the moves",
    92: "a coordinate offset (G92) moves the program's origin",
    92.1: "a coordinate offset reset (G92.1)",
    92.2: "a coordinate offset reset (G92.2)",
    92.3: "a coordinate offset restore (G92.3)",
    10: "G10 sets offsets or tool data the compensation cannot follow",
    52: "a local coordinate offset (G52) moves the program's origin",
}
_CYCLES = {73, 74, 76, 81, 82, 83, 84, 85, 86, 87, 88, 89}


class GcodeError(InputError):
    """A program the compensation cannot follow; ``line`` is its 1-based line number."""

    def __init__(self, message: str, *, line: int, source: str | None = None):
        super().__init__(f"line {line}: {message}", source=source)
        self.line = line


class _NoMotion(GcodeError):
    """Axis words with no motion mode in force: refused, or passed through (``why``)."""

    def __init__(self, why: str, *, line: int, source: str | None = None):
        super().__init__(why, line=line, source=source)
        self.why = why


@dataclass(frozen=True)
class Word:
    """One word of a line: letter (upper case), value, and its span in the line's text."""

    letter: str
    value: float
    start: int
    end: int


@dataclass(frozen=True)
class Move:
    """One programmed move (one line), positions in mm in the program's frame.

    Attributes
    ----------
    kind : int
        :data:`RAPID`, :data:`LINE`, :data:`ARC_CW` or :data:`ARC_CCW`.
    line : int
        1-based line number in the program.
    start, end : ndarray, shape (3,), mm
        Absolute positions (x, y, z) before and after the move.
    centre : ndarray, shape (3,), mm, or None
        An arc's centre (its normal coordinate is that of the start).
    plane : int
        17, 18 or 19 (the plane the line was in).
    inch : bool
        The line is in inches (G20): its coordinates are written back in inches.
    incremental : bool
        G91: the axis words are written as increments.
    arc_absolute : bool
        G90.1: I, J, K are absolute positions.
    arc_r : bool
        The arc was written with R (written back with R).
    axes : tuple of str
        The axis words (X, Y, Z) the line wrote.
    spans : tuple of (int, int)
        Spans of the line's X, Y, Z, I, J, K, R words (replaced when it is rewritten).
    motion_word : bool
        The line held its motion G-word (G0-G3).
    lower : bool
        The line is written in lower case.
    compact : bool
        The line's words are not separated by spaces.
    known : tuple of bool
        Whether x, y, z of the end are known (False after G28/G30/G53 or a line passed
        through, until the program gives that axis again).
    motion_before : int or None
        The motion mode in force before the line (set by an earlier move, or by a line
        that only sets it: ``G00;``, ``G01 F5.``), None if none was.
    """

    kind: int
    line: int
    start: np.ndarray
    end: np.ndarray
    centre: np.ndarray | None
    plane: int
    inch: bool
    incremental: bool
    arc_absolute: bool
    arc_r: bool
    axes: tuple[str, ...]
    spans: tuple[tuple[int, int], ...]
    motion_word: bool
    lower: bool
    compact: bool
    known: tuple[bool, bool, bool] = (True, True, True)
    motion_before: int | None = None

    @property
    def feed(self) -> bool:
        """A feed move (G1, G2, G3), which carries the cutting force."""
        return self.kind != RAPID


@dataclass(frozen=True)
class Program:
    """A parsed program.

    Attributes
    ----------
    source : str
        Where it came from (for messages).
    lines : tuple of str
        Every line, verbatim, without its line ending.
    newline : str
        The line ending to write back (``"\\n"`` or ``"\\r\\n"``).
    final_newline : bool
        The text ended with a line ending.
    moves : tuple of Move
        The moves, in program order.
    move_at_line : dict of int to int
        Line number -> index in ``moves``.
    warnings : tuple of str
        One per line passed through unchanged, and notes (an axis taken as 0).
    """

    source: str
    lines: tuple[str, ...]
    newline: str
    final_newline: bool
    moves: tuple[Move, ...]
    move_at_line: dict[int, int]
    warnings: tuple[str, ...] = ()

    @property
    def n_moves(self) -> int:
        return len(self.moves)


@dataclass
class _State:
    """The modal state while reading (mutable; private to the parser)."""

    units_inch: bool = False
    incremental: bool = False
    arc_absolute: bool = False
    plane: int = 17
    motion: int | None = None
    work_offset: float | None = None
    moved: bool = False
    framed: bool = False  # a move in the program's frame happened (not only G28/G30/G53)
    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    known: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=bool))
    passing: str = ""  # G41/G42 or G93 in force under pass_through: the reason


def _strip_comments(text: str, line: int, src: str | None) -> tuple[str, bool]:
    """The line with its comments blanked (same length), and whether it held code."""
    out = []
    depth = False
    for i, ch in enumerate(text):
        if depth:
            out.append(" ")
            if ch == ")":
                depth = False
        elif ch == "(":
            depth = True
            out.append(" ")
        elif ch == ";":
            out.append(" " * (len(text) - i))
            break
        else:
            out.append(ch)
    if depth:
        raise GcodeError("a comment '(' is not closed on its line", line=line, source=src)
    code = "".join(out)
    return code, bool(code.strip())


#: What a character that cannot start a word usually is (added to the refusal).
_NOT_GCODE = {
    "$": " ('$' starts a grbl system command, not G-code)",
    "*": " ('*' starts a RepRap line checksum, not G-code)",
    "^": " (LinuxCNC's polar coordinates, @ and ^, are not supported)",
    "@": " (LinuxCNC's polar coordinates, @ and ^, are not supported)",
    ",": " (a decimal comma: write 1.5, not 1,5)",
    "E": " (an extruder word: a 3D printer's program, not a machining one)",
}


def _words(code: str, line: int, src: str | None) -> list[Word]:
    """The words of a comment-free line; refuses what is not a letter and a number."""
    if "#" in code:
        raise GcodeError(
            "'#' parameters are not supported (the values are not known before running)",
            line=line,
            source=src,
        )
    if "[" in code:
        raise GcodeError("'[' expressions are not supported (give numbers)", line=line, source=src)
    words: list[Word] = []
    i = 0
    n = len(code)
    while i < n:
        ch = code[i]
        if ch.isspace():
            i += 1
            continue
        if ch == "#":
            raise GcodeError(
                "'#' parameters are not supported (the values are not known before running)",
                line=line,
                source=src,
            )
        if ch == "[":
            raise GcodeError("'[' expressions are not supported (give numbers)", line=line, source=src)
        if ch == "%" and not code[:i].strip():
            i += 1
            continue
        m = _WORD.match(code, i)
        if m is None or m.group(1).upper() not in _LETTERS:
            what = code[i : i + 12].strip()
            letter = ch.upper()
            if letter == "O":
                raise GcodeError(
                    "O-words (subprograms, loops, conditions) are not supported", line=line, source=src
                )
            hint = _NOT_GCODE.get(ch.upper(), "")
            raise GcodeError(
                f"cannot read {what!r}: expected a word, a letter and a number{hint}", line=line, source=src
            )
        value = float(m.group(2) + m.group(3))
        if not abs(value) <= MAX_WORD_VALUE:
            digits = m.group(3)[:12] + ("..." if len(m.group(3)) > 12 else "")
            raise GcodeError(
                f"{m.group(1).upper()}{m.group(2)}{digits}: a number beyond {MAX_WORD_VALUE:g}, which no "
                "program holds",
                line=line,
                source=src,
            )
        words.append(Word(m.group(1).upper(), value, m.start(), m.end()))
        i = m.end()
    return words


def _refusal(words: list[Word], state: _State) -> str:
    """Why a line cannot be compensated ("" when it can)."""
    gs = [round(w.value, 1) for w in words if w.letter == "G"]
    for g in gs:
        if g in _REFUSED_G:
            return _REFUSED_G[g]
        if g in _CYCLES or int(g) in _CYCLES:
            return f"canned cycle G{g:g} (its moves are made by the controller)"
        if g not in _KEEP_G:
            return f"G{g:g} is not supported"
        if (
            g in (54, 55, 56, 57, 58, 59, 59.1, 59.2, 59.3)
            and state.framed
            and g != (state.work_offset or 54)
        ):
            return f"G{g:g} changes the work offset after the first move (the program's origin would move)"
    for w in words:
        if w.letter == "M" and round(w.value) in (98, 99):
            return f"M{w.value:g} calls or returns from a subprogram"
    return ""


def _value(words: list[Word], letter: str) -> Word | None:
    found = [w for w in words if w.letter == letter]
    return found[-1] if found else None


def _modal(words: list[Word], state: _State) -> tuple[int | None, bool]:
    """Apply the line's modal G-words; its motion word (or None) and whether it is G28/G30/G53."""
    motion = None
    special = False
    for w in words:
        if w.letter != "G":
            continue
        g = round(w.value, 1)
        if g in (0, 1, 2, 3):
            motion = int(g)
        elif g == 80:
            state.motion = None
        elif g in (17, 18, 19):
            state.plane = int(g)
        elif g in (20, 21):
            state.units_inch = g == 20
        elif g in (90, 91):
            state.incremental = g == 91
        elif g in (90.1, 91.1):
            state.arc_absolute = g == 90.1
        elif g in (28, 30, 53):
            special = True
        elif 54 <= g <= 59.3:
            state.work_offset = g
    return motion, special


def _target(words: list[Word], state: _State, line: int, src: str | None) -> tuple[np.ndarray, list[str]]:
    """The end position (mm) of a move from its axis words; refuses an unknown axis it needs."""
    scale = MM_PER_INCH if state.units_inch else 1.0
    end = state.pos.copy()
    axes = []
    for k, a in enumerate("XYZ"):
        w = _value(words, a)
        if w is None:
            continue
        axes.append(a)
        v = w.value * scale
        if state.incremental:
            if not state.known[k]:
                raise GcodeError(
                    f"an incremental {a} move from an unknown {a} (after G28/G30/G53 or a line passed "
                    f"through): give {a} absolutely (G90) first",
                    line=line,
                    source=src,
                )
            end[k] = state.pos[k] + v
        else:
            end[k] = v
    return end, axes


def _arc_centre(words, state: _State, start, end, kind, line, src) -> tuple[np.ndarray, bool]:
    """An arc's centre (mm; normal coordinate that of the start) and whether it was given by R."""
    a, b, _ = PLANE_AXES[state.plane]
    scale = MM_PER_INCH if state.units_inch else 1.0
    r = _value(words, "R")
    ij = {k: _value(words, _CENTRE_WORD[k]) for k in (a, b)}
    other = _CENTRE_WORD[PLANE_AXES[state.plane][2]]
    if _value(words, other) is not None:
        raise GcodeError(f"{other} is not an arc centre word in G{state.plane}", line=line, source=src)
    if _value(words, "P") is not None:
        raise GcodeError("arcs of several turns (P) are not supported", line=line, source=src)
    if r is not None and any(v is not None for v in ij.values()):
        raise GcodeError("an arc takes R or I/J/K, not both", line=line, source=src)
    centre = start.copy()
    if r is None:
        if all(v is None for v in ij.values()):
            raise GcodeError(
                f"arc without its centre: give {_CENTRE_WORD[a]}/{_CENTRE_WORD[b]} or R",
                line=line,
                source=src,
            )
        for k, w in ij.items():
            v = 0.0 if w is None else w.value * scale
            centre[k] = v if state.arc_absolute else start[k] + v
        r0 = math.hypot(start[a] - centre[a], start[b] - centre[b])
        r1 = math.hypot(end[a] - centre[a], end[b] - centre[b])
        tol = ARC_RADIUS_TOL_INCH * MM_PER_INCH if state.units_inch else ARC_RADIUS_TOL_MM
        if r0 <= 0 or abs(r1 - r0) > max(tol, ARC_RADIUS_RTOL * max(r0, r1)):
            raise GcodeError(
                f"arc radius at the start {r0:.6g} mm and at the end {r1:.6g} mm differ: the centre does "
                "not fit the end point",
                line=line,
                source=src,
            )
        return centre, False
    R = r.value * scale
    dx, dy = end[a] - start[a], end[b] - start[b]
    chord = math.hypot(dx, dy)
    if chord == 0 or R == 0:
        raise GcodeError(
            "an R-format arc needs distinct start and end points and R != 0", line=line, source=src
        )
    half = chord / 2
    if half > abs(R) + (R_TOL_INCH * MM_PER_INCH if state.units_inch else R_TOL_MM):
        raise GcodeError(
            f"R {abs(R):.6g} mm is less than half the chord ({half:.6g} mm)", line=line, source=src
        )
    h = math.sqrt(max(R * R - half * half, 0.0))
    # The centre lies left of the chord for a G3 arc of less than a half turn (R > 0).
    side = (1.0 if kind == ARC_CCW else -1.0) * (1.0 if R > 0 else -1.0)
    centre[a] = start[a] + dx / 2 - side * h * dy / chord
    centre[b] = start[b] + dy / 2 + side * h * dx / chord
    return centre, True


def parse_program(text: str, source: str | None = None, *, pass_through: bool = False) -> Program:
    """Read a program's text (see the module docstring for what is understood).

    Parameters
    ----------
    text : str
    source : str, optional
        Its name, for messages.
    pass_through : bool
        Keep the lines that cannot be compensated unchanged (a warning each) instead of
        refusing the program.

    Returns
    -------
    Program

    Raises
    ------
    GcodeError
        Naming the line: an unsupported construct, a malformed word, an arc whose centre
        does not fit, an incremental move from an unknown position.
    """
    newline = "\r\n" if "\r\n" in text else ("\r" if "\r" in text and "\n" not in text else "\n")
    final = text.endswith(("\n", "\r"))
    lines = tuple(text.splitlines())
    st = _State()
    moves: list[Move] = []
    warnings: list[str] = []
    at: dict[int, int] = {}
    percent = None  # the program is delimited by '%' lines (then the second one ends it)
    for i, raw in enumerate(lines):
        n = i + 1
        code, has_code = _strip_comments(raw, n, source)
        if not has_code:
            continue
        stripped = code.lstrip()
        if percent is None:
            percent = stripped.rstrip() == "%"
        elif percent and stripped.rstrip() == "%":
            break  # the program's end: what follows is kept verbatim, never run
        if stripped.startswith("/"):
            why = "block delete '/': whether the line runs is the operator's choice"
            _pass_or_refuse(why, [], st, n, source, pass_through, warnings)
            continue
        if _PROGRAM_NUMBER.fullmatch(code):
            continue  # "O1234" alone: a program number (Fanuc), kept verbatim
        words = _words(code, n, source)
        gs = {round(w.value, 1) for w in words if w.letter == "G"}
        if st.passing and (40 in gs if st.passing.startswith("cutter") else 94 in gs):
            st.passing = ""  # the line that ends the region is read as usual
        why = st.passing or _refusal(words, st)
        if why:
            _update_passing(words, st)
            _pass_or_refuse(why, words, st, n, source, pass_through, warnings)
            continue
        try:
            move = _line_move(raw, words, st, n, source, warnings)
        except _NoMotion as e:
            _pass_or_refuse(e.why, words, st, n, source, pass_through, warnings)
            continue
        if move is not None:
            at[n] = len(moves)
            moves.append(move)
        if any(w.letter == "M" and w.value in (2, 30) for w in words):
            break  # M2/M30 end the program: the lines after it are kept verbatim, never run
    named = tuple(f"{source}: {w}" for w in warnings) if source else tuple(warnings)
    return Program(source or "<program>", lines, newline, final, tuple(moves), at, named)


def _update_passing(words: list[Word], st: _State) -> None:
    """Enter a passed-through region (G41/G42 until G40, G93 until G94)."""
    gs = {round(w.value, 1) for w in words if w.letter == "G"}
    if gs & {41, 42, 41.1, 42.1}:
        st.passing = "cutter-radius compensation is on (G41/G42 until G40)"
    elif 93 in gs:
        st.passing = "inverse-time feed is on (G93 until G94)"


def _pass_or_refuse(why, words, st: _State, n, source, pass_through, warnings) -> None:
    if not pass_through:
        raise GcodeError(f"{why}; use --pass-through to keep such lines unchanged", line=n, source=source)
    warnings.append(f"line {n}: kept unchanged, not compensated: {why}")
    for k, a in enumerate("XYZ"):
        if any(w.letter == a for w in words) or not words:
            st.known[k] = False
    st.moved = st.framed = True


def _line_move(raw, words, st: _State, n, source, warnings) -> Move | None:
    """Apply one supported line to the state; its move, if it moves."""
    motion, special = _modal(words, st)
    has_axes = any(w.letter in "XYZ" for w in words)
    if special:  # G28/G30/G53: kept verbatim; the axes they move become unknown
        for k, a in enumerate("XYZ"):
            if any(w.letter == a for w in words) or not has_axes:
                st.known[k] = False
        if motion is not None:
            st.motion = motion
        st.moved = True
        return None
    before = st.motion
    if motion is not None:
        st.motion = motion
    has_centre = any(w.letter in "IJKR" for w in words)
    if not has_axes and not (has_centre and st.motion in (2, 3)):
        if has_centre:
            raise GcodeError("I/J/K/R words outside an arc", line=n, source=source)
        return None
    if st.motion is None:
        raise _NoMotion(
            "axis words with no motion mode in force (after G80, or before any G0-G3): whether the axes "
            "move is the controller's choice (RS274/NGC refuses the line, Fanuc moves in the last G0/G1)",
            line=n,
            source=source,
        )
    if not st.moved:
        _first_move(words, st, n, source, warnings)
    end, axes = _target(words, st, n, source)
    start = st.pos.copy()
    centre, arc_r = None, False
    if st.motion in (2, 3):
        centre, arc_r = _arc_centre(words, st, start, end, st.motion, n, source)
    elif has_centre:
        raise GcodeError("I/J/K/R words on a straight move", line=n, source=source)
    spans = tuple((w.start, w.end) for w in words if w.letter in "XYZIJKR")
    move = Move(
        kind=st.motion,
        line=n,
        start=start,
        end=end,
        centre=centre,
        plane=st.plane,
        inch=st.units_inch,
        incremental=st.incremental,
        arc_absolute=st.arc_absolute,
        arc_r=arc_r,
        axes=tuple(axes),
        spans=spans,
        motion_word=motion is not None,
        lower=_code_lower(raw, words),
        compact=_compact(raw, words),
        known=(
            bool(st.known[0]) or "X" in axes,
            bool(st.known[1]) or "Y" in axes,
            bool(st.known[2]) or "Z" in axes,
        ),
        motion_before=before,
    )
    st.pos = end
    for a in axes:
        st.known["XYZ".index(a)] = True
    st.moved = st.framed = True
    return move


def _first_move(words, st: _State, n, source, warnings) -> None:
    """The program's first move: an arc refused (its centre is from an unknown point), a feed taken as
    an approach, axes never set taken as 0 (each said)."""
    if st.motion in (2, 3):
        raise GcodeError(
            f"an arc (G{st.motion}) as the first move starts wherever the machine stands: its centre "
            "is from an unknown point; move to its start first (G0/G1)",
            line=n,
            source=source,
        )
    if st.motion != 0:
        warnings.append(
            f"line {n}: the first move is a feed from wherever the machine stands: taken as an "
            "approach (no force; it goes to the next cut's compensated start)"
        )
    for k, a in enumerate("XYZ"):
        if not st.known[k] and not any(w.letter == a for w in words):
            warnings.append(f"line {n}: {a} was never set before the first move: taken as 0")
            st.known[k] = True
    st.known[:] = True  # the program's origin: where the machine stands for the axes it never gives


def _code_lower(raw: str, words: list[Word]) -> bool:
    """The line's coordinate words are written in lower case."""
    coords = [w for w in words if w.letter in "XYZIJKR"] or words
    return all(raw[w.start].islower() for w in coords)


def _compact(raw: str, words: list[Word]) -> bool:
    """No space separates the line's coordinate words from the words before them."""
    idx = [j for j, w in enumerate(words) if w.letter in "XYZIJKR" and j > 0]
    return bool(idx) and all(words[j].start == words[j - 1].end for j in idx)


# ---------------------------------------------------------------------- writing


@dataclass(frozen=True)
class Piece:
    """One output move: where a programmed move's part ends, and for an arc its centre.

    Attributes
    ----------
    kind : int
        :data:`LINE`, :data:`ARC_CW` or :data:`ARC_CCW` (:data:`RAPID` for a rapid).
    end : ndarray, shape (3,), mm
        Commanded end, program frame.
    centre : ndarray, shape (3,), mm, or None
        An arc's commanded centre.
    """

    kind: int
    end: np.ndarray
    centre: np.ndarray | None = None


def _fmt(v: float, inch: bool, extra: int = 0) -> str:
    """A coordinate with its decimal point (0.1 um in mm, 0.25 um in inch; ``extra`` digits more)."""
    s = f"{v:.{(5 if inch else 4) + extra}f}"
    s = s.rstrip("0")
    if s in ("-0.", "+0."):
        s = "0."
    return s


def written_resolution_mm(inch: bool, extra: int = 0) -> float:
    """The step (mm) of the coordinates :func:`render_program` writes (:func:`_fmt`)."""
    return (MM_PER_INCH * 1e-5 if inch else 1e-4) * 10.0**-extra


def _rounded(v: float, inch: bool, extra: int) -> float:
    """``v`` (in the program's units) as :func:`_fmt` writes it."""
    return float(_fmt(v, inch, extra))


def _coord_words(
    move: Move, piece: Piece, start: np.ndarray, axes: tuple[int, ...], extra: int = 0
) -> list[str]:
    """The X/Y/Z (and I/J/K or R) words of a piece that starts at ``start`` (mm). An increment
    (G91) is the difference of the two positions as written, so that rounding never adds up."""
    scale = 1.0 / MM_PER_INCH if move.inch else 1.0
    inch = move.inch
    words = []
    for k in axes:
        v = piece.end[k] * scale
        if move.incremental:
            v = _rounded(v, inch, extra) - _rounded(start[k] * scale, inch, extra)
        words.append("XYZ"[k] + _fmt(v, inch, extra))
    if piece.kind in (ARC_CW, ARC_CCW):
        a, b, _ = PLANE_AXES[move.plane]
        c = piece.centre
        if move.arc_r:
            r = math.hypot(start[a] - c[a], start[b] - c[b])
            r = -r if _sweep(piece.kind, start, piece.end, c, move.plane) > math.pi else r
            words.append("R" + _fmt(r * scale, inch, extra))
        else:
            for k in sorted((a, b)):
                v = (
                    c[k] * scale
                    if move.arc_absolute
                    else c[k] * scale - _rounded(start[k] * scale, inch, extra)
                )
                words.append(_CENTRE_WORD[k] + _fmt(v, inch, extra))
    return words


def _sweep(kind: int, start, end, centre, plane: int) -> float:
    """The absolute angle (rad) an arc turns through, in (0, 2 pi]."""
    a, b, _ = PLANE_AXES[plane]
    t0 = math.atan2(start[b] - centre[b], start[a] - centre[a])
    t1 = math.atan2(end[b] - centre[b], end[a] - centre[a])
    d = (t1 - t0) % (2 * math.pi) if kind == ARC_CCW else (t0 - t1) % (2 * math.pi)
    return d if d > 1e-12 else 2 * math.pi


def _style(words: list[str], move: Move) -> str:
    text = ("" if move.compact else " ").join(words)
    return text.lower() if move.lower else text


def render_program(
    program: Program, outputs: dict[int, list[Piece]], axes: dict[int, tuple[int, ...]], extra_digits: int = 0
) -> str:
    """The program with the moves of ``outputs`` rewritten and every other line verbatim.

    Parameters
    ----------
    program : Program
    outputs : dict of int to list of Piece
        Move index -> the pieces that replace it (their ends in mm, program frame). A move
        not in ``outputs`` is written verbatim (absolute mode) or, in incremental mode, with
        its increments from where the previous output left the tool.
    axes : dict of int to tuple of int
        Move index -> the axes (0, 1, 2) its pieces write.
    extra_digits : int
        Digits written beyond 0.1 um (mm) or 0.25 um (inch), for a tolerance finer than those.

    Returns
    -------
    str
        The new program text, with the input's line endings.
    """
    out_lines: list[str] = []
    pos = None  # commanded position after the previous move (mm)
    mode = None  # the motion mode the output has in force
    mode_in = None  # the motion mode the input has in force after its previous move
    for n, raw in enumerate(program.lines, start=1):
        idx = program.move_at_line.get(n)
        if idx is None:
            out_lines.append(raw)
            continue
        mv = program.moves[idx]
        if mv.motion_before != mode_in:  # a line kept verbatim set it (``G00;``): in the output too
            mode = mv.motion_before
        mode_in = mv.kind
        start = mv.start if pos is None else pos
        pieces = outputs.get(idx)
        written = tuple("XYZ".index(a) for a in mv.axes)
        if pieces is None:
            pieces = [Piece(mv.kind, mv.end, mv.centre)]
            # verbatim, unless its increments start elsewhere than the program's (an earlier
            # line left the tool at a compensated point along an axis this line writes)
            if not mv.incremental or np.array_equal(start[list(written)], mv.start[list(written)]):
                out_lines.append(raw if mv.motion_word or mode == mv.kind else _with_motion(raw, mv))
                pos, mode = _moved(start, mv.end, written), mv.kind
                continue
        ax = axes.get(idx, written)
        first = True
        for pc in pieces:
            words = _coord_words(mv, pc, start, ax, extra_digits)
            if first:
                if not mv.motion_word and mode != pc.kind:
                    words = [_G[pc.kind], *words]
                out_lines.append(_rewrite(raw, mv, _style(words, mv)))
                first = False
            else:
                out_lines.append(_style([_G[pc.kind], *words], mv))
            start, mode = _moved(start, pc.end, ax), pc.kind
        pos = start
    text = program.newline.join(out_lines)
    return text + program.newline if program.final_newline else text


_G = {RAPID: "G0", LINE: "G1", ARC_CW: "G2", ARC_CCW: "G3"}


def _moved(start: np.ndarray, end: np.ndarray, written) -> np.ndarray:
    """Where a line leaves the tool: ``end`` along the axes it writes, ``start`` along the others
    (an axis a line does not name stays put, compensated or not, in G90 as in G91)."""
    out = np.array(start, dtype=float)
    idx = list(written)
    out[idx] = end[idx]
    return out


def _with_motion(raw: str, move: Move) -> str:
    """A verbatim move line with its motion word added before its first coordinate word."""
    at = min(s for s, _ in move.spans)
    g = _G[move.kind].lower() if move.lower else _G[move.kind]
    return raw[:at] + g + ("" if move.compact else " ") + raw[at:]


def _rewrite(raw: str, move: Move, coords: str) -> str:
    """The line with its coordinate words replaced by ``coords`` (at the first one's place)."""
    spans = sorted(move.spans)
    out = raw[: spans[0][0]] + coords
    prev = spans[0][1]
    for s, e in spans[1:]:
        gap = raw[prev:s]
        out += gap[:-1] if gap.endswith(" ") and gap.strip() == "" and gap else gap
        prev = e
    return out + raw[prev:]
