"""Fuzz classes of the table and recording readers: identify, model/fit, simulate, sensor, report.

Each :class:`~helpers.fuzz.FuzzClass` starts from a VALID input that a lab would feed the
command (written by stiffmap's own writers where it has one: ``sensors.io.write_recording``
for the recordings, ``ReportData.to_dict`` for ``data.json``) and draws malformed variants:
the generic text and byte mutations of :mod:`helpers.fuzz` and, per format, wrong types,
extreme and non-finite numbers and degenerate data (a constant or all-zero signal, a
single row, repeated rows, a sample rate of 0, an int16 or a text channel...).

The valid seeds are built once per process (:func:`functools.cache`); they are small, so
that one case runs in tens of milliseconds.
"""

from __future__ import annotations

import base64
import functools
import io
import json
import math
import re
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from helpers.fuzz import EXTREME_NUMBERS, WRONG_TYPES, FuzzCase, FuzzClass, mutated_bytes, mutated_text
from stiffmap.loads import forces_matrix, paper9
from stiffmap.models import PRR3, DeltaRobot
from stiffmap.sensors.io import write_recording
from stiffmap.sim.traces import DaqChain, LoadSteps, simulate_trace

__all__ = [
    "FUZZ_CLASSES",
    "K_TRUE",
    "model_seeds",
    "identify_files",
    "sensor_trace",
    "sensor_recording",
    "report_data_json",
    "csv_text",
    "write_tdms_channels",
    "write_mat_variables",
    "write_text_channels",
]

#: Values a degenerate numeric column may be made of (all cells the same).
_DEGENERATE_VALUES = (0.0, 1e-300, 5e-324, -1e-300, 1e308, -1e308, 1e300, 1e-30, 1.0, 1e30)


def csv_text(header, rows, fmt: str = "{:.9g}", sep: str = ",") -> str:
    """CSV text of a header and rows of numbers (or strings, written as they are)."""
    lines = [sep.join(header)]
    for r in rows:
        lines.append(sep.join(v if isinstance(v, str) else fmt.format(v) for v in r))
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- identify
#: A Delta robot's stiffness at one position, N/mm (SPD, a little anisotropic).
K_TRUE = np.array([[2.0, 0.3, 0.1], [0.3, 2.5, -0.2], [0.1, -0.2, 8.0]])


@functools.cache
def identify_design() -> tuple[np.ndarray, np.ndarray, int]:
    """The reference study's nine load cases (N) and two repeats of displacements (mm)."""
    rng = np.random.default_rng(16)
    F = forces_matrix(paper9())
    repeats = 2
    D = np.concatenate(
        [np.linalg.solve(K_TRUE, F) + rng.normal(scale=2e-3, size=F.shape) for _ in range(repeats)], axis=1
    )
    return F, D, repeats


def forces_text(F: np.ndarray | None = None) -> str:
    F = identify_design()[0] if F is None else F
    return csv_text(("fx", "fy", "fz"), F.T, "{:.6g}")


def displacements_text(D: np.ndarray | None = None, with_repeat: bool = True) -> str:
    F, D0, repeats = identify_design()
    D = D0 if D is None else D
    n = F.shape[1]
    if not with_repeat:
        return csv_text(("dx", "dy", "dz"), D[:, :n].T, "{:.6g}")
    rows = [[*D[:, i], str(i // n + 1)] for i in range(D.shape[1])]
    return csv_text(("dx", "dy", "dz", "repeat"), rows, "{:.6g}")


@functools.cache
def wrench_texts() -> tuple[str, str]:
    """Forces with moments (N, N*mm) and displacements with rotations (mm, rad): a 6x6 K."""
    rng = np.random.default_rng(61)
    Kt = K_TRUE
    Kr = np.diag([4e5, 5e5, 9e5])  # N*mm/rad
    K = np.zeros((6, 6))
    K[:3, :3], K[3:, 3:] = Kt, Kr
    n = 12
    F = np.vstack([rng.normal(scale=5.0, size=(3, n)), rng.normal(scale=500.0, size=(3, n))])
    D = np.linalg.solve(K, F)
    D[:3] += rng.normal(scale=2e-3, size=(3, n))
    D[3:] += rng.normal(scale=2e-6, size=(3, n))
    ft = csv_text(("fx", "fy", "fz", "mx", "my", "mz"), F.T, "{:.6g}")
    dt = csv_text(("dx", "dy", "dz", "rx", "ry", "rz"), D.T, "{:.6g}")
    return ft, dt


def _identify_case(forces: str | bytes, disp: str | bytes, blamed: str | None, note: str = "", json_out=True):
    enc = lambda x: x if isinstance(x, bytes) else x.encode()  # noqa: E731
    argv = ("identify", "{dir}/forces.csv", "{dir}/displacements.csv") + (("--json",) if json_out else ())
    files = {"forces.csv": enc(forces), "displacements.csv": enc(disp)}
    return FuzzCase(files, argv, blamed, note, check=identify_check)


#: The asymmetry test's level (a flag below it): stiffmap.identify.ASYMMETRY_P, 1 % (docs/identification.md).
ASYMMETRY_LEVEL = 0.01
_NOT_A_NUMBER = re.compile(r"(?<![\w/])(nan|-?inf(inity)?)(?![\w/])", re.IGNORECASE)


def identify_check(directory: Path, o) -> str:
    """What a run of ``identify`` that printed K left wrong: a value printed as nan or inf (the
    text prints ``n/a``, the JSON ``null``); the asymmetry test's p outside [0, 1]; p and the
    ``asymmetric`` flag disagreeing (p below 1 % flags it, p at or above 1 % does not)."""
    if o.code not in (0, 1) or not o.stdout.strip():
        return ""
    if _NOT_A_NUMBER.search(o.stdout):
        return f"printed {_NOT_A_NUMBER.search(o.stdout).group(0)!r} as a value"
    if o.stdout.lstrip().startswith("{"):

        def refuse(name):
            raise ValueError(name)

        try:
            data = json.loads(o.stdout, parse_constant=refuse)
        except ValueError as e:
            return f"JSON output not finite: {e}"
        p, flags = data.get("asymmetry_p"), data.get("flags", [])
    else:
        m = re.search(r"\(test p = ([^)]*)\)", o.stdout)
        if m is None:
            return "no asymmetry test p printed beside K's asymmetry"
        try:
            p = None if m.group(1) == "n/a" else float(m.group(1))
        except ValueError:
            return f"test p = {m.group(1)!r}: not a number"
        flags = [ln.split("flag:", 1)[1].strip() for ln in o.stdout.splitlines() if ln.startswith("flag:")]
    if p is None:
        return ""
    if not 0.0 <= p <= 1.0:
        return f"asymmetry test p = {p} outside [0, 1]"
    flagged = any(f.startswith("asymmetric:") for f in flags)
    if not o.stdout.lstrip().startswith("{") and abs(p - ASYMMETRY_LEVEL) < 6e-4:
        return ""  # printed to 2 digits: 0.0095-0.0105 print as 0.0095..0.01 either side of the level
    if (p < ASYMMETRY_LEVEL) != flagged:
        return f"asymmetry test p = {p:.3g} but the asymmetric flag {'given' if flagged else 'missing'}"
    return ""


@st.composite
def degenerate_matrix(draw, M: np.ndarray) -> tuple[np.ndarray, str]:
    """A degenerate variant of a data matrix (components x cases) and what was done to it."""
    kind = draw(
        st.sampled_from(
            (
                "constant",
                "scaled",
                "one column constant",
                "one component zero",
                "repeated identical cases",
                "single case",
                "one line",
            )
        )
    )
    X = M.copy()
    v = draw(st.sampled_from(_DEGENERATE_VALUES))
    if kind == "constant":
        X[:] = v
    elif kind == "scaled":
        with np.errstate(over="ignore"):
            X = X * v
    elif kind == "one column constant":
        X[:, draw(st.integers(0, X.shape[1] - 1))] = v
    elif kind == "one component zero":
        X[draw(st.integers(0, X.shape[0] - 1))] = 0.0
    elif kind == "repeated identical cases":
        X[:] = X[:, [0]]
    elif kind == "single case":
        X = X[:, :1]
    elif kind == "one line":  # every case along the same direction
        X = np.outer(X[:, 0], np.linspace(0.5, 2.0, X.shape[1]))
    return X, f"{kind} ({v:g})"


@st.composite
def identify_forces_cases(draw) -> FuzzCase:
    return _identify_case(
        draw(mutated_text(forces_text())), displacements_text(), "forces.csv", "mutated forces"
    )


@st.composite
def identify_displacements_cases(draw) -> FuzzCase:
    data = draw(mutated_text(displacements_text()))
    return _identify_case(forces_text(), data, "displacements.csv", "mutated displacements")


@st.composite
def identify_wrench_cases(draw) -> FuzzCase:
    ft, dt = wrench_texts()
    if draw(st.booleans()):
        return _identify_case(draw(mutated_text(ft)), dt, "forces.csv", "mutated wrench forces")
    return _identify_case(ft, draw(mutated_text(dt)), "displacements.csv", "mutated 6-column displacements")


def _rows_text(text: str, n: int) -> str:
    """A CSV text's header and its first ``n`` rows."""
    return "".join(text.splitlines(keepends=True)[: n + 1])


@st.composite
def identify_test_paths(draw) -> FuzzCase:
    """The asymmetry test's edge paths: fewer residual degrees of freedom than K - K^T has
    entries (q = 3 of a 3x3 K, 15 of a 6x6: the law undefined), none at all, and noise-free
    displacements (K's covariance zero: singular)."""
    six = draw(st.booleans())
    ft, dt = wrench_texts() if six else (forces_text(), displacements_text(with_repeat=False))
    m = 6 if six else 3
    kind = draw(st.sampled_from(("few cases", "noise-free")))
    if kind == "few cases":  # dof = (n - m) per component: 0 .. q-1 and one above
        n = draw(st.integers(m, m + (3 if six else 2)))
        ft, dt = _rows_text(ft, n), _rows_text(dt, n)
        what = f"{n} load cases of a {m}x{m} K"
    else:
        F = np.array([[float(v) for v in ln.split(",")] for ln in ft.splitlines()[1:]]).T
        K = np.zeros((6, 6)) if six else K_TRUE
        if six:
            K[:3, :3], K[3:, 3:] = K_TRUE, np.diag([4e5, 5e5, 9e5])
        scale = draw(st.sampled_from((1.0, 1.0 + 1e-9, -1.0)))  # exact, a common scale, K^T's sign
        D = np.linalg.solve(K if scale > 0 else -K.T, F) * abs(scale)
        cols = ("dx", "dy", "dz", "rx", "ry", "rz")[:m]
        dt = csv_text(cols, D.T, "{:.17g}")
        what = f"noise-free displacements of a {m}x{m} K (scale {scale:g})"
    return _identify_case(ft, dt, None, what, json_out=draw(st.booleans()))


@st.composite
def identify_degenerate_cases(draw) -> FuzzCase:
    F, D, _ = identify_design()
    n = F.shape[1]
    if draw(st.integers(0, 3)) == 0:
        return draw(identify_test_paths())
    if draw(st.booleans()):
        D2, what = draw(degenerate_matrix(D[:, :n]))
        if D2.shape[1] != n:  # a single case: the forces file says one too
            F = F[:, : D2.shape[1]]
        text = displacements_text(D2, with_repeat=False)
        method = draw(st.sampled_from(("compliance", "paper", "spd")))
        case = _identify_case(forces_text(F), text, None, f"displacements {what}, --method {method}")
        blamed = "displacements.csv" if D2.shape[1] == n else None
        return FuzzCase(case.files, case.argv + ("--method", method), blamed, case.note, check=identify_check)
    F2, what = draw(degenerate_matrix(F))
    D2 = D[:, : F2.shape[1]]
    return _identify_case(
        forces_text(F2), displacements_text(D2, with_repeat=False), None, f"forces {what}", json_out=False
    )


def identify_files() -> tuple[str, str]:
    """The valid forces and displacements CSV texts (for tests of the right answer)."""
    return forces_text(), displacements_text()


# --------------------------------------------------------------------------- model, fit
@functools.cache
def model_seeds() -> dict[str, str]:
    """Valid points and measurement files of the 3PRR (planar) and the Delta."""
    P2 = np.array([[400.0, 200.0], [300.0, 300.0], [500.0, 270.0], [400.0, 120.0]])
    P3 = np.array([[0.0, 0.0, -310.0], [66.67, -66.67, -200.0], [-200.0, 200.0, -400.0]])
    m2 = PRR3()
    rng = np.random.default_rng(5)
    rows = []
    for p in P2:
        for u in ((1.0, 0.0), (0.0, 1.0)):
            f = 490.5 * np.asarray(u)
            e = float(m2.static_error(p[None], f)[0] @ np.asarray(u))
            rows.append([*p, *f, e + rng.normal(scale=1e-4), 2e-4])
    static = csv_text(("x", "y", "fx", "fy", "value_mm", "std_mm"), rows, "{:.9g}")
    m3 = DeltaRobot()
    K3 = m3.stiffness(P3)
    krows = [[*p, *k.ravel()] for p, k in zip(P3, K3, strict=True)]
    kcols = [f"k{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
    stiff = csv_text(("x", "y", "z", *kcols), krows, "{:.9g}")
    return {
        "points2": csv_text(("x", "y"), P2, "{:g}"),
        "points3": csv_text(("x", "y", "z"), P3, "{:g}"),
        "static2": static,
        "stiffness3": stiff,
    }


@st.composite
def model_points_cases(draw) -> FuzzCase:
    mech, key = draw(st.sampled_from((("3prr", "points2"), ("delta", "points3"))))
    data = draw(mutated_text(model_seeds()[key]))
    return FuzzCase(
        {"points.csv": data}, ("model", mech, "--points", "{dir}/points.csv", "--json"), "points.csv"
    )


@st.composite
def fit_cases(draw) -> FuzzCase:
    mech, key = draw(st.sampled_from((("3prr", "static2"), ("delta", "stiffness3"))))
    data = draw(mutated_text(model_seeds()[key]))
    return FuzzCase({"meas.csv": data}, ("fit", mech, "{dir}/meas.csv", "--json"), "meas.csv")


@st.composite
def fit_degenerate_cases(draw) -> FuzzCase:
    """Measurements with one column made degenerate (constant, zero, huge, tiny)."""
    mech, key = draw(st.sampled_from((("3prr", "static2"), ("delta", "stiffness3"))))
    lines = model_seeds()[key].splitlines()
    header = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    j = draw(st.integers(0, len(header) - 1))
    v = draw(st.sampled_from([*(f"{x:g}" for x in _DEGENERATE_VALUES), "1e-320"]))
    kind = draw(st.sampled_from(("column", "rows identical", "one row")))
    if kind == "column":
        for r in rows:
            r[j] = v
    elif kind == "rows identical":
        rows = [rows[0]] * len(rows)
    else:
        rows = rows[:1]
    text = "\n".join(",".join(r) for r in [header, *rows]) + "\n"
    return FuzzCase(
        {"meas.csv": text.encode()},
        ("fit", mech, "{dir}/meas.csv", "--json"),
        "meas.csv",
        f"{kind} {header[j]}={v}",
    )


# --------------------------------------------------------------------------- simulate
LOADS_TEXT = "fx,fy,fz,label\n0,4.905,0,0.5 kg +y\n-4.905,0,0,0.5 kg -x\n0,0,-4.905,0.5 kg -z\n"
POSITIONS_TEXT = "x,y,z\n0,0,-310\n66.67,-66.67,-200\n"


@st.composite
def simulate_cases(draw) -> FuzzCase:
    which = draw(st.sampled_from(("loads", "positions")))
    loads = draw(mutated_text(LOADS_TEXT)) if which == "loads" else LOADS_TEXT.encode()
    pos = draw(mutated_text(POSITIONS_TEXT)) if which == "positions" else POSITIONS_TEXT.encode()
    argv = (
        "simulate",
        "{dir}/out",
        "--truth-only",
        "--loads",
        "{dir}/loads.csv",
        "--positions",
        "{dir}/positions.csv",
        "--json",
    )
    return FuzzCase({"loads.csv": loads, "positions.csv": pos}, argv, f"{which}.csv", f"mutated {which}")


# --------------------------------------------------------------------------- sensor
#: A short recording: 100 Hz, 1.5 s plateaus of 0, 50, 40, 30, 20, 10, 0 kgf (about 1400 samples).
_CHAIN = DaqChain(sample_rate_hz=100.0)
_STEPS = LoadSteps(plateau_s=1.5, transition_s=0.5)


@functools.cache
def sensor_trace():
    return simulate_trace(static_error_mm=0.5, chain=_CHAIN, protocol=_STEPS, seed=16, source="rec")


@functools.cache
def sensor_recording(fmt: str) -> bytes:
    """The valid recording written by ``write_recording`` (``csv``, ``tdms``, ``mat``), or as
    DAQ software writes text: ``txt`` (tab-separated) and ``semicolon`` (``;``, decimal comma)."""
    rec = sensor_trace().recording
    if fmt in ("csv", "tdms", "mat"):
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / f"rec.{fmt}"
            write_recording(rec, p)
            return p.read_bytes()
    cols = np.column_stack([rec.time_s, rec.displacement_v, rec.load])
    if fmt == "txt":
        return csv_text(("time_s", "displacement_v", "load_kgf"), cols, "{:.6f}", "\t").encode()
    if fmt == "semicolon":
        text = csv_text(("time_s", "displacement_v", "load_kgf"), cols, "{:.6f}", ";")
        return text.replace(".", ",").encode()
    raise ValueError(fmt)


_SUFFIX = {"csv": ".csv", "txt": ".txt", "semicolon": ".csv", "tdms": ".tdms", "mat": ".mat"}


def _sensor_case(name: str, data: bytes, extra=(), note: str = "", blamed: str | None = "") -> FuzzCase:
    argv = ("sensor", "{dir}/" + name, "--json", *extra)
    return FuzzCase({name: data}, argv, name if blamed == "" else blamed, note)


@st.composite
def sensor_text_cases(draw) -> FuzzCase:
    fmt = draw(st.sampled_from(("csv", "txt", "semicolon")))
    data = draw(mutated_text(sensor_recording(fmt).decode()))
    return _sensor_case("rec" + _SUFFIX[fmt], data, note=f"mutated {fmt}")


@st.composite
def sensor_binary_cases(draw) -> FuzzCase:
    fmt = draw(st.sampled_from(("tdms", "mat")))
    data = draw(mutated_bytes(sensor_recording(fmt)))
    return _sensor_case("rec" + _SUFFIX[fmt], data, note=f"byte-mutated {fmt}")


# Structured recordings: the channels as arrays of any dtype, written in any format.
def write_tdms_channels(
    channels: dict, props: dict | None = None, time_channel: bool = True, only: str | None = None
) -> bytes:
    """A TDMS file of channels of any dtype in group ``daq``, ``props`` on each but time_s
    (``only``: on that channel only)."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    objs = [RootObject({}), GroupObject("daq")]
    for name, values in channels.items():
        p = dict(props or {}) if name != "time_s" and only in (None, name) else {}
        if name == "time_s" and not time_channel:
            continue
        objs.append(ChannelObject("daq", name, values, p))
    buf = io.BytesIO()
    with TdmsWriter(buf) as w:
        w.write_segment(objs)
    return buf.getvalue()


def write_mat_variables(channels: dict, extra: dict | None = None) -> bytes:
    """A MAT v5 file of the channels (as columns) and of ``extra`` variables as they are."""
    import scipy.io

    buf = io.BytesIO()
    d = {
        k: (v.reshape(-1, 1) if isinstance(v, np.ndarray) and v.dtype.kind != "U" else v)
        for k, v in channels.items()
    }
    scipy.io.savemat(buf, {**d, **(extra or {})})
    return buf.getvalue()


def write_text_channels(channels: dict, sep: str = ",") -> bytes:
    """A CSV of the channels, each value written with ``str`` (text channels as they are)."""
    names = list(channels)
    cols = [np.asarray(channels[k]).astype(str) for k in names]
    n = max((c.size for c in cols), default=0)
    lines = [sep.join(names)]
    for i in range(n):
        lines.append(sep.join(c[i] if i < c.size else "" for c in cols))
    return ("\n".join(lines) + "\n").encode()


#: What a degenerate recording may be: (name, description) pairs for the notes.
DEGENERATE_RECORDINGS = (
    "constant displacement",
    "zero displacement",
    "nan displacement",
    "constant load",
    "zero load",
    "huge load",
    "huge displacement",
    "int16 displacement",
    "int16 load",
    "text displacement",
    "text load",
    "two samples",
    "one sample",
    "no samples",
    "repeated rows",
    "constant time",
    "huge time",
    "tiny time step",
    "bool displacement",
    "complex displacement",
    "2-d displacement",
)


@st.composite
def degenerate_channels(draw) -> tuple[dict, str]:
    """The channels (time_s, displacement_v, load_kgf) of a degenerate recording."""
    rec = sensor_trace().recording
    t, v, ld = rec.time_s.copy(), rec.displacement_v.copy(), rec.load.copy()
    kind = draw(st.sampled_from(DEGENERATE_RECORDINGS))
    val = draw(st.sampled_from(_DEGENERATE_VALUES))
    ch: dict = {"time_s": t, "displacement_v": v, "load_kgf": ld}
    if kind == "constant displacement":
        ch["displacement_v"] = np.full_like(v, draw(st.sampled_from((0.0, 1.234, -3.0, 7.99))))
    elif kind == "zero displacement":
        ch["displacement_v"] = np.zeros_like(v)
    elif kind == "nan displacement":
        ch["displacement_v"] = np.full_like(v, np.nan)
    elif kind == "constant load":
        ch["load_kgf"] = np.full_like(ld, draw(st.sampled_from((0.0, 50.0, 1e300))))
    elif kind == "zero load":
        ch["load_kgf"] = np.zeros_like(ld)
    elif kind == "huge load":
        with np.errstate(over="ignore"):
            ch["load_kgf"] = ld * val
    elif kind == "huge displacement":
        with np.errstate(over="ignore"):
            ch["displacement_v"] = v * val
    elif kind == "int16 displacement":
        ch["displacement_v"] = np.round(v * 3276.8).astype(np.int16)
    elif kind == "int16 load":
        ch["load_kgf"] = np.round(ld).astype(np.int16)
    elif kind == "text displacement":
        ch["displacement_v"] = np.array([f"{x:.4f} V" for x in v])
    elif kind == "text load":
        ch["load_kgf"] = np.array(["n/a"] * ld.size)
    elif kind in ("two samples", "one sample", "no samples"):
        k = {"two samples": 2, "one sample": 1, "no samples": 0}[kind]
        ch = {k2: a[:k] for k2, a in ch.items()}
    elif kind == "repeated rows":
        ch = {k2: np.repeat(a[:1], a.size) for k2, a in ch.items()}
    elif kind == "constant time":
        ch["time_s"] = np.full_like(t, 1.0)
    elif kind == "huge time":
        ch["time_s"] = t * 1e306
    elif kind == "tiny time step":
        ch["time_s"] = t * 1e-300
    elif kind == "bool displacement":
        ch["displacement_v"] = v > 0
    elif kind == "complex displacement":
        ch["displacement_v"] = v + 1j * v
    elif kind == "2-d displacement":
        ch["displacement_v"] = np.column_stack([v, v])
    return ch, f"{kind} ({val:g})"


@st.composite
def sensor_degenerate_cases(draw) -> FuzzCase:
    ch, what = draw(degenerate_channels())
    fmt = draw(st.sampled_from(("csv", "tdms", "mat")))
    try:
        if fmt == "csv":
            if any(np.ndim(a) != 1 for a in ch.values()):
                ch = {k: np.ravel(a) for k, a in ch.items()}
            data = write_text_channels(ch)
        elif fmt == "tdms":
            chans = {k: (np.ravel(a) if a.dtype.kind != "c" else a.real) for k, a in ch.items()}
            chans = {k: (a.astype(np.uint8) if a.dtype.kind == "b" else a) for k, a in chans.items()}
            data = write_tdms_channels(chans, {}, True)
        else:
            data = write_mat_variables({k: a for k, a in ch.items()}, {})
    except Exception as e:  # a writer that cannot write it: an empty file instead (still a case)
        data, what = b"", f"{what}; writer refused: {type(e).__name__}"
    return _sensor_case("rec" + _SUFFIX[fmt], data, note=f"{fmt}: {what}")


#: Wrong values of a property or a scalar variable that holds a number.
_BAD_SCALARS = (
    "abc",
    "",
    "0.001 s",
    0.0,
    -0.01,
    math.nan,
    math.inf,
    1e-320,
    1e300,
    -1e300,
    np.int32(0),
    np.int64(10**15),
)


@st.composite
def sensor_waveform_cases(draw) -> FuzzCase:
    """TDMS waveform properties and MAT sample rates of the wrong type or value."""
    rec = sensor_trace().recording
    ch = {"displacement_v": rec.displacement_v, "load_kgf": rec.load}
    bad = draw(st.sampled_from(_BAD_SCALARS))
    if draw(st.booleans()):
        key = draw(st.sampled_from(("wf_increment", "wf_start_offset")))
        props = {"wf_increment": 0.01, "wf_start_offset": 0.0, key: bad}
        data = write_tdms_channels(ch, props, time_channel=False)
        return _sensor_case("rec.tdms", data, note=f"tdms {key}={bad!r}")
    key = draw(st.sampled_from(("sample_rate_hz", "fs")))
    extra = {key: bad if not isinstance(bad, str) else np.array(bad)}
    if draw(st.integers(0, 5)) == 0:  # a vector where a scalar belongs
        extra[key] = np.array([[100.0, 100.0]])
    data = write_mat_variables(ch, extra)
    return _sensor_case("rec.mat", data, note=f"mat {key}={bad!r}")


def _is_float(text: str) -> bool:
    """Whether the command line's number options take ``text`` (ASCII that ``float`` reads)."""
    try:
        float(text)
    except ValueError:
        return False
    return text.isascii()


@st.composite
def _number_text(draw, floats_only: bool = False) -> str:
    """Text where a number belongs: extreme, non-finite or not a number at all.

    ``floats_only``: only texts that Python's ``float`` reads (those the command line's
    number options accept; others are refused by the option parser before stiffmap runs).
    """
    pool = EXTREME_NUMBERS + WRONG_TYPES
    if floats_only:
        pool = tuple(t for t in pool if _is_float(t))
    return draw(
        st.one_of(
            st.sampled_from(pool),
            st.floats(allow_nan=True, allow_infinity=True).map(repr),
            st.integers(-100, 100).map(str),
        )
    )


@st.composite
def sensor_option_cases(draw) -> FuzzCase:
    """The valid CSV recording with a table of steps, hand plateaus or numbers out of range."""
    data = sensor_recording("csv")
    opt = draw(
        st.sampled_from(
            (
                "--steps-kgf",
                "--steps-n",
                "--step-times",
                "--scale-um-per-v",
                "--range-v",
                "--load-n-per-v",
                "--g",
                "--reference-load-n",
                "--window-s",
                "--min-plateau-s",
                "--threshold-sigma",
                "--channel-map",
            )
        )
    )
    if opt in ("--steps-kgf", "--steps-n"):
        vals = draw(st.lists(_number_text(), min_size=0, max_size=9))
        text = ",".join(vals)
    elif opt == "--step-times":
        pairs = draw(st.lists(st.tuples(_number_text(), _number_text()), min_size=0, max_size=8))
        sep = draw(st.sampled_from(("-", ":")))
        text = ",".join(f"{a}{sep}{b}" for a, b in pairs)
    elif opt == "--channel-map":
        key = draw(st.sampled_from(("rate", "time", "load", "displacement", "group", "fs", "x")))
        text = f"{key}={draw(_number_text())}" + draw(st.sampled_from(("", ",time=none", ",load=none")))
    else:
        text = draw(_number_text(floats_only=True))
    extra = [opt + "=" + text]
    if opt == "--load-n-per-v":
        extra += ["--channel-map", "load=load_kgf", "--load-unit", "V"]
    return _sensor_case("rec.csv", data, tuple(extra), note=f"{opt}={text!r}", blamed=None)


@st.composite
def sensor_batch_cases(draw) -> FuzzCase:
    """Two recordings, one valid and one malformed: the command goes on with the good one."""
    good = sensor_recording("tdms")
    bad_case = draw(st.one_of(sensor_degenerate_cases(), sensor_binary_cases(), sensor_text_cases()))
    ((name, data),) = bad_case.files.items()
    bad_name = "bad" + Path(name).suffix
    files = {"good.tdms": good, bad_name: data}
    argv = ("sensor", "{dir}/good.tdms", "{dir}/" + bad_name, "--json")
    return FuzzCase(files, argv, bad_name, "batch: " + bad_case.note)


INDEX_TEXT = "x,y,ux,uy,file,axis_sign\n400,200,1,0,rec.tdms,1\n400,200,0,1,rec.tdms,-1\n"


@st.composite
def sensor_index_cases(draw) -> FuzzCase:
    data = draw(mutated_text(INDEX_TEXT))
    files = {"index.csv": data, "rec.tdms": sensor_recording("tdms")}
    return FuzzCase(files, ("sensor", "--index", "{dir}/index.csv", "--json"), "index.csv", "mutated index")


# --------------------------------------------------------------------------- report
@functools.cache
def report_data_json(kind: str = "sensor") -> str:
    """A small campaign's report data: ``sensor`` (four points, two directions, a fitted
    model) or ``vision`` (three positions of a Delta, three load cases, two repeats)."""
    from stiffmap.report.data import (
        BoardImage,
        CampaignInfo,
        LoadData,
        MeasuredStiffness,
        Parameter,
        ReportData,
        SensorResults,
        SetupItem,
    )
    from stiffmap.report.png import grey_png

    if kind == "vision":
        P = np.array([[0.0, 0.0, -310.0], [66.67, -66.67, -200.0], [-200.0, 200.0, -400.0]])
        K = np.stack([K_TRUE * s for s in (1.0, 0.8, 1.3)])
        K[2, 0, 1] = np.nan  # a failed position
        F = forces_matrix(paper9()[:3]).T
        # With the diagnostics' data: displacement vectors and residuals, a set-up summary and
        # an image with its boards (a 4 x 6 grey PNG).
        vec = np.linalg.solve(K_TRUE, F.T).T[None, :, None, :] * np.ones((3, 3, 2, 3))
        png = base64.b64encode(grey_png(np.arange(24, dtype=np.uint8).reshape(4, 6))).decode()
        data = ReportData(
            campaign=CampaignInfo(name="fuzz", kind="vision", date="2026-01-01"),
            measured=MeasuredStiffness.from_K(P, K, np.abs(K) * 0.02),
            loads=LoadData(
                labels=("0.5 kg +y", "0.5 kg -x", "0.5 kg -z"),
                forces=F,
                norms=np.linalg.norm(vec, axis=3),
                vectors=vec,
                residuals=vec * 0.01,
            ),
            setup=(SetupItem("robot", "delta"), SetupItem("images", "36 of 36 measured")),
            board_image=BoardImage("i.png", png, np.array([12.0, 8.0]), 2.0, np.ones((2, 2)), ("m", "m")),
        )
        return json.dumps(data.to_dict())

    pts = np.array([[400.0, 420.0], [400.0, 320.0], [400.0, 220.0], [400.0, 120.0]] * 2)
    err = np.array([31.0, 28.5, 27.0, 29.0, 55.0, 50.0, 48.0, 52.0])
    data = ReportData(
        campaign=CampaignInfo(name="fuzz", kind="sensor", date="2026-01-01"),
        sensor=SensorResults(
            points=pts,
            direction=("x",) * 4 + ("y",) * 4,
            error_um=err,
            error_std_um=np.full(8, 0.8),
            model_error_um=err * 1.02,
            model_name="3prr",
            parameters=(Parameter("kj", 1200.0, 35.0, "N/mm"),),
            step_load_n=np.tile([0.0, 98.1, 196.2, np.nan], (8, 1)),
            step_um=np.tile([0.1, 20.0, 40.2, np.nan], (8, 1)),
            fit_um_per_n=np.full(8, 0.204),
            fit_intercept_um=np.full(8, 0.05),
        ),
    )
    return json.dumps(data.to_dict())


_JSON_BAD = (None, "abc", "", 0, -1, 1e308, -1e308, 5e-324, True, [], {}, [[1, 2], [3]], "x" * 5000, [None])


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:3]):
            yield from _paths(v, (*prefix, i))


@st.composite
def mutated_json(draw, valid: str) -> bytes:
    """A JSON document with one value replaced, a key removed or added (or a text mutation)."""
    obj = json.loads(valid)
    paths = [p for p in _paths(obj) if p]
    path = draw(st.sampled_from(paths))
    kind = draw(st.sampled_from(("replace", "delete", "add", "nan", "text")))
    if kind == "text":
        return draw(mutated_text(valid))
    parent = obj
    for k in path[:-1]:
        parent = parent[k]
    last = path[-1]
    if kind == "replace":
        parent[last] = draw(st.sampled_from(_JSON_BAD))
    elif kind == "delete":
        del parent[last]
    elif kind == "add":
        if isinstance(parent, dict):
            parent["unexpected"] = 1
        else:
            parent.append(draw(st.sampled_from(_JSON_BAD)))
    else:
        parent[last] = draw(st.sampled_from((math.nan, math.inf, -math.inf)))
    return json.dumps(obj, allow_nan=True).encode()


@st.composite
def report_cases(draw) -> FuzzCase:
    data = draw(mutated_json(report_data_json(draw(st.sampled_from(("sensor", "vision"))))))
    return FuzzCase(
        {"data.json": data}, ("report", "{dir}/data.json", "{dir}/out", "--no-png", "--json"), "data.json"
    )


# --------------------------------------------------------------------------- the classes
FUZZ_CLASSES: list[FuzzClass] = [
    FuzzClass("identify: forces CSV", identify_forces_cases(), "stiffmap identify, mutated forces.csv"),
    FuzzClass(
        "identify: displacements CSV",
        identify_displacements_cases(),
        "stiffmap identify, mutated displacements.csv (with a repeat column)",
    ),
    FuzzClass("identify: 6-column wrench CSVs", identify_wrench_cases(), "a 6x6 K: moments and rotations"),
    FuzzClass(
        "identify: degenerate data",
        identify_degenerate_cases(),
        "constant, all-zero, tiny or huge, repeated or single load cases; the asymmetry test's paths",
    ),
    FuzzClass("model: --points CSV", model_points_cases(), "stiffmap model delta|3prr --points"),
    FuzzClass("fit: measurements CSV", fit_cases(), "stiffmap fit, static errors (3prr) and K (delta)"),
    FuzzClass("fit: degenerate measurements", fit_degenerate_cases(), "a column constant, rows identical"),
    FuzzClass("simulate: --loads / --positions CSV", simulate_cases(), "stiffmap simulate --truth-only"),
    FuzzClass("sensor: CSV/TXT recording", sensor_text_cases(), "comma, tab and semicolon/decimal comma"),
    FuzzClass("sensor: TDMS/MAT bytes", sensor_binary_cases(), "byte-level corruption of TDMS and MAT"),
    FuzzClass("sensor: degenerate recordings", sensor_degenerate_cases(), "constant, int16, text channels"),
    FuzzClass("sensor: waveform and sample rate", sensor_waveform_cases(), "wf_increment, sample_rate_hz"),
    FuzzClass("sensor: options", sensor_option_cases(), "steps, step times and numbers out of range"),
    FuzzClass("sensor: several recordings", sensor_batch_cases(), "one bad recording beside a good one"),
    FuzzClass("sensor: --index CSV", sensor_index_cases(), "the index of a sensor campaign"),
    FuzzClass("report: data.json", report_cases(), "stiffmap report DATA.json"),
]
