"""Fuzzing the command line: malformed inputs in, one clear message (or a right answer) out.

A :class:`FuzzCase` is pure data: the files of one invocation (name -> bytes) and its
command line, with ``{dir}`` standing for the fresh directory the files are written to.
:func:`run_case` writes them and runs ``stiffmap`` **in this process** (through
``stiffmap.cli.main.main``, the same guard the console script uses), with warnings as
errors (but stiffmap's own warnings, which the CLI prints as one ``warning:`` line) and a
time limit. :func:`classify` says what happened:

``ok``         exit 0
``clear``      exit 1 or 2, an ``error:`` (or ``warning:``) line that names the blamed file
``unnamed``    exit 1 or 2 with a message that does not name the blamed file
``silent``     a non-zero exit without any ``error:``/``warning:`` line
``late``       a case that must be refused before anything is done (``FuzzCase.must_refuse``: a
               robot file outside the campaign, an unknown tip frame) ran (exit 0 or 1)
``wrong``      silently wrong: the case says what must be said (``FuzzCase.expect``: a swapped
               rig file, a camera that measured nothing), results were given (exit 0 or 1) and no
               ``error:``/``warning:`` line says it (a refusal, exit 2, is right); or a run that
               exited 0 whose output the case's ``oracle`` (an independent computation of the
               right answer: ``helpers.fuzz_robots.RobotCase``) finds wrong; or the case's
               ``check`` found what the run left wrong (an output off its tolerance, an input
               changed, an output or temporary file left by a failed run: ``Outcome.detail``)
``bug``        stiffmap's guard caught an unexpected exception (exit 3, "internal error")
``traceback``  an exception escaped the guard (or ``Traceback`` was printed)
``hang``       the time limit passed

The property every fuzz test checks (:func:`assert_handled`) is that the outcome is
``ok`` or ``clear``. :data:`FuzzClass` groups cases of one input class (a reader and the
command that uses it) for the tests and for ``benchmarks/bench_fuzz.py``.

Mutations of valid files (:func:`mutated_text`, :func:`mutated_bytes`) are hypothesis
strategies, so a failing case shrinks to a small one.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import re
import shutil
import signal
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hypothesis import strategies as st

from stiffmap.cli import main as cli_main
from stiffmap.errors import StiffmapWarning

#: Seconds one invocation may take before it counts as a hang.
TIME_LIMIT_S = 20.0

OUTCOMES = ("ok", "clear", "unnamed", "silent", "late", "wrong", "bug", "traceback", "hang")
HANDLED = ("ok", "clear")


@dataclass(frozen=True)
class FuzzCase:
    """One invocation: files written to a fresh directory, then ``stiffmap ARGV``.

    ``argv`` items may hold ``{dir}`` (the directory). ``blamed`` is the name (relative
    to the directory) of the file an error message must name; None when any message will
    do (e.g. several files are malformed at once). ``expect``: when the input is wrong in a
    way that gives plausible results (a rig file of another rig), a text a ``warning:`` or
    ``error:`` line must hold when the command gives results (exit 0 or 1; a refusal, exit 2,
    is right too); None when success is right. ``must_refuse``: the input must be refused
    before anything is done (exit 2). ``links``: symbolic links to make (name -> target, both
    relative to the directory). In the bytes of a ``.toml`` file, ``{dir}`` is the directory.
    ``check``: called with the directory and the outcome after the run (before the directory is
    removed); what it returns, when not empty, is what the run left wrong: the outcome is then
    ``wrong`` (unless worse) and the text its ``detail``.
    """

    files: dict[str, bytes]
    argv: tuple[str, ...]
    blamed: str | None = None
    note: str = ""
    expect: str | None = None
    must_refuse: bool = False
    links: dict[str, str] = field(default_factory=dict)
    check: Callable[[Path, Outcome], str] | None = field(default=None, compare=False)

    def __repr__(self) -> str:
        # Short, for hypothesis's report of a failing case (the files' bytes can be megabytes).
        files = ", ".join(f"{k!r}: <{len(v)} bytes {v[:24]!r}...>" for k, v in self.files.items())
        return f"FuzzCase(files={{{files}}}, argv={self.argv!r}, blamed={self.blamed!r}, note={self.note!r})"

    def _repr_pretty_(self, p, cycle) -> None:  # hypothesis prints dataclasses field by field otherwise
        p.text(repr(self))


@dataclass(frozen=True)
class FuzzClass:
    """A class of malformed inputs: a name (for reports) and a strategy of cases.

    ``slow``: each case runs a whole campaign or capture (seconds): the benchmark draws fewer.
    """

    name: str
    cases: st.SearchStrategy[FuzzCase]
    description: str = ""
    slow: bool = False


@dataclass
class Outcome:
    code: int | None
    stdout: str
    stderr: str
    kind: str = ""
    seconds: float = 0.0
    escaped: BaseException | None = field(default=None, repr=False)
    detail: str = ""


class _Hang(BaseException):
    """Raised by the alarm; a BaseException so that the CLI's guard does not catch it."""


@contextlib.contextmanager
def _time_limit(seconds: float):
    if seconds <= 0 or not hasattr(signal, "setitimer"):
        yield
        return

    def on_alarm(signum, frame):
        raise _Hang(f"more than {seconds:g} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def write_case(case: FuzzCase, directory: Path) -> list[str]:
    """Write the case's files into ``directory``; return its command line."""
    for name, data in case.files.items():
        p = directory / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data.replace(b"{dir}", str(directory).encode()) if name.endswith(".toml") else data)
    for name, target in getattr(case, "links", {}).items():
        p = directory / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.symlink_to(directory / target)
    return [a.replace("{dir}", str(directory)) for a in case.argv]


def run_argv(argv: list[str], *, time_limit: float = TIME_LIMIT_S) -> Outcome:
    """Run ``stiffmap argv`` in this process; capture its streams, exit status and fate."""
    out, err = io.StringIO(), io.StringIO()
    code: int | None = None
    escaped: BaseException | None = None
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.simplefilter("default", StiffmapWarning)
        old_out, old_err = sys.stdout, sys.stderr
        sys.stdout, sys.stderr = out, err
        try:
            with _time_limit(time_limit):
                code = cli_main.main(argv)
        except _Hang as e:
            escaped = e
        except BaseException as e:  # noqa: BLE001 - anything that escapes the guard is the finding
            escaped = e
        finally:
            sys.stdout, sys.stderr = old_out, old_err
    o = Outcome(code, out.getvalue(), err.getvalue(), seconds=time.perf_counter() - t0, escaped=escaped)
    return o


def classify(o: Outcome, blamed: str | None, expect: str | None = None, must_refuse: bool = False) -> str:
    """The outcome's kind (see the module docstring)."""
    if isinstance(o.escaped, _Hang):
        return "hang"
    if o.escaped is not None or "Traceback (most recent call last)" in o.stderr + o.stdout:
        return "traceback"
    if o.code == cli_main.EXIT_BUG or "internal error" in o.stderr:
        return "bug"
    if must_refuse and o.code in (0, 1):
        return "late"
    lines = [ln for ln in o.stderr.splitlines() if ln.startswith(("error:", "warning:"))]
    if expect is not None and o.code in (0, 1) and not any(expect in ln for ln in lines):
        return "wrong"  # results given (exit 0 or 1) without the word that says they are wrong
    if o.code == 0:
        return "ok"
    if not lines or o.code not in (1, 2):
        return "silent"
    if blamed is not None and not any(_names(ln, blamed) for ln in lines):
        return "unnamed"
    return "clear"


def _names(line: str, blamed: str) -> bool:
    """Whether a message line names the file ``blamed`` (by its name or its path)."""
    return Path(blamed).name in line


def run_case(case: FuzzCase, *, time_limit: float = TIME_LIMIT_S) -> Outcome:
    """Write the case to a fresh directory, run it, classify it, remove the directory."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-fuzz-"))
    try:
        o = run_argv(write_case(case, d), time_limit=time_limit)
        check = getattr(case, "check", None)
        if check is not None and not isinstance(o.escaped, _Hang):
            o.detail = check(d, o)
    finally:
        shutil.rmtree(d, ignore_errors=True)
    o.kind = classify(o, case.blamed, getattr(case, "expect", None), getattr(case, "must_refuse", False))
    if o.detail and o.kind in (*HANDLED, "unnamed", "silent"):
        o.kind = "wrong"
    oracle = getattr(case, "oracle", None)  # an independent check of a successful run's output
    why = oracle(o) if o.kind == "ok" and oracle is not None else None
    if why:
        o.kind = "wrong"
        o.stderr += f"\noracle: {why}\n"
    return o


def assert_handled(case: FuzzCase, o: Outcome) -> None:
    """The fuzz property: the command succeeded, or said clearly what is wrong with which file."""
    if o.kind in HANDLED:
        return
    detail = f"{type(o.escaped).__name__}: {o.escaped}" if o.escaped is not None else o.detail
    raise AssertionError(
        f"{o.kind}: stiffmap {' '.join(case.argv)} (exit {o.code}) {detail}\n"
        f"files: {', '.join(f'{k} ({len(v)} bytes)' for k, v in case.files.items())}"
        f"{' - ' + case.note if case.note else ''}\nstderr: {o.stderr[-2000:]}"
    )


# --------------------------------------------------------------------------- mutations
#: Numbers a reader must refuse, or take for what they are, without crashing.
EXTREME_NUMBERS = (
    "0",
    "-0",
    "1e308",
    "-1e308",
    "1e309",
    "1e-308",
    "5e-324",
    "1e300",
    "-1e-300",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "9" * 400,
    "1" * 5000,
    "0x1F",
    "1_000",
    "١٢٣",
)
#: Text where a number belongs.
WRONG_TYPES = ("", " ", "abc", "true", "null", "[]", "{}", "1,2", "1;2", '"1"', "é", "\x00", "1.2.3", "--1")

_NUMBER = re.compile(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def _replace_number(text: str, k: int, new: str) -> str:
    spans = [m.span() for m in _NUMBER.finditer(text)]
    if not spans:
        return text + new
    a, b = spans[k % len(spans)]
    return text[:a] + new + text[b:]


@st.composite
def mutated_text(draw, valid: str, *, encoding: str = "utf-8") -> bytes:
    """A malformed variant of a valid text file (CSV, JSON, TOML): one mutation, as bytes."""
    kind = draw(
        st.sampled_from(
            (
                "extreme number",
                "wrong type",
                "several numbers",
                "truncate",
                "drop line",
                "duplicate line",
                "empty",
                "header only",
                "huge field",
                "separator",
                "encoding",
                "byte corruption",
                "whitespace",
                "json instead",
            )
        )
    )
    t = valid
    lines = t.splitlines(keepends=True)
    n_num = max(1, len(_NUMBER.findall(t)))
    if kind == "extreme number":
        t = _replace_number(t, draw(st.integers(0, n_num - 1)), draw(st.sampled_from(EXTREME_NUMBERS)))
    elif kind == "wrong type":
        t = _replace_number(t, draw(st.integers(0, n_num - 1)), draw(st.sampled_from(WRONG_TYPES)))
    elif kind == "several numbers":
        value = draw(st.sampled_from(EXTREME_NUMBERS + WRONG_TYPES))
        for k in draw(st.lists(st.integers(0, n_num - 1), min_size=2, max_size=12)):
            t = _replace_number(t, k, value)
    elif kind == "truncate":
        t = t[: draw(st.integers(0, max(0, len(t) - 1)))]
    elif kind == "drop line" and lines:
        i = draw(st.integers(0, len(lines) - 1))
        t = "".join(lines[:i] + lines[i + 1 :])
    elif kind == "duplicate line" and lines:
        i = draw(st.integers(0, len(lines) - 1))
        t = "".join(lines[: i + 1] + lines[i:])
    elif kind == "empty":
        t = ""
    elif kind == "header only":
        t = lines[0] if lines else ""
    elif kind == "huge field":
        huge = draw(st.sampled_from(("7", "x", "-"))) * 200_000
        t = _replace_number(t, draw(st.integers(0, n_num - 1)), huge)
    elif kind == "separator":
        swaps = ((",", ";"), (",", "\t"), (",", " "), ("\n", "\r"), (".", ","), ("=", ":"))
        a, b = draw(st.sampled_from(swaps))
        t = t.replace(a, b)
    elif kind == "encoding":
        enc = draw(st.sampled_from(("utf-16", "utf-32", "latin-1-bom", "cp1252")))
        if enc == "latin-1-bom":
            return b"\xef\xbb\xbf" + t.encode("utf-8") + "é".encode("latin-1")
        return t.encode(enc, errors="replace")
    elif kind == "byte corruption":
        return draw(mutated_bytes(t.encode(encoding)))
    elif kind == "whitespace":
        t = "\n\n  " + t.replace(",", " , ") + "\n\n\n"
    elif kind == "json instead":  # the same table written as JSON (a list of rows: issue 27)
        t = _as_json(t)
    return t.encode(encoding, errors="surrogateescape")


def _as_json(text: str) -> str:
    """A CSV table as the JSON list of its rows (``[{"x": "1", ...}, ...]``); JSON stays as it is."""
    if text.lstrip()[:1] in ("{", "["):
        return text
    rows = list(csv.reader(ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")))
    if not rows:
        return "[]"
    return json.dumps([dict(zip(rows[0], r, strict=False)) for r in rows[1:]], indent=1)


@st.composite
def mutated_bytes(draw, valid: bytes) -> bytes:
    """A malformed variant of a valid binary file: truncated, bytes overwritten, or zeroed."""
    b = bytearray(valid)
    kind = draw(st.sampled_from(("truncate", "overwrite", "zero block", "insert", "empty")))
    if kind == "empty" or not b:
        return b""
    if kind == "truncate":
        return bytes(b[: draw(st.integers(0, len(b) - 1))])
    if kind == "overwrite":
        for _ in range(draw(st.integers(1, 16))):
            b[draw(st.integers(0, len(b) - 1))] = draw(st.integers(0, 255))
        return bytes(b)
    if kind == "zero block":
        i = draw(st.integers(0, len(b) - 1))
        n = draw(st.integers(1, 4096))
        b[i : i + n] = bytes(len(b[i : i + n]))
        return bytes(b)
    i = draw(st.integers(0, len(b)))
    return bytes(b[:i]) + draw(st.binary(min_size=1, max_size=256)) + bytes(b[i:])


def cases_of(
    files: st.SearchStrategy[dict[str, bytes]], argv: tuple[str, ...], blamed: str | None, note: str = ""
) -> st.SearchStrategy[FuzzCase]:
    """Cases from a strategy of file sets, a fixed command line and the file to blame."""
    return files.map(lambda fs: FuzzCase(files=fs, argv=tuple(argv), blamed=blamed, note=note))
