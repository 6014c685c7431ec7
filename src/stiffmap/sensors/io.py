"""Read and write DAQ recordings: CSV, NI TDMS (npTDMS) and MATLAB .mat (SciPy).

All three formats hold the same thing: a displacement channel in volts, an
optional load channel and the time of each sample, named by a
:class:`~stiffmap.sensors.recording.ChannelMap` (defaults ``time_s``,
``displacement_v``, ``load_kgf``).

- **CSV**: a header row, one row per sample; an empty cell or ``nan`` is a
  missing sample (a dropout).
- **TDMS**: channels found by name in any group (or in ``group``); the time is a
  time channel when there is one, else the waveform properties of the
  displacement channel (``wf_start_offset + i * wf_increment``), as NI DAQmx and
  LabVIEW write them.
- **MAT** (v4 to v7; v7.3 is HDF5, which SciPy does not read): variables by
  name, 1-D or n x 1, at the top level or as fields of the struct ``group``; a
  scalar ``sample_rate_hz`` (or ``fs``) stands in for a time vector.

Every problem raises :class:`~stiffmap.errors.InputError` naming the file and the
channel. Writers write atomically and never touch an existing raw file except
by replacing it whole.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import logging
import os
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import FieldError, InputError, StiffmapWarning
from ..io import atomic_write_bytes, atomic_write_text, read_csv_columns
from .matfile import mat5_variables
from .recording import ChannelMap, Recording, check_sample_rate, load_unit_from_name

__all__ = ["read_recording", "write_recording", "FORMATS", "format_from_path"]

#: File formats by suffix.
FORMATS = {".csv": "csv", ".txt": "csv", ".tdms": "tdms", ".mat": "mat"}


def format_from_path(path: str | os.PathLike) -> str:
    """``"csv"``, ``"tdms"`` or ``"mat"`` from the file suffix (InputError otherwise)."""
    suf = Path(path).suffix.lower()
    if suf not in FORMATS:
        raise InputError(
            f"unknown recording format {suf or '(no suffix)'!r}; expected .csv, .tdms or .mat",
            source=str(path),
        )
    return FORMATS[suf]


def _time_from_rate(n: int, fs: float | None, src: str, where: str) -> np.ndarray:
    if fs is None:
        raise FieldError(
            "channel_map",
            f"no time channel ({where}) and no sample rate; name the time column with "
            "{channel_map} time=COL or give rate=HZ",
            source=src,
        )
    return np.arange(n) * (1.0 / fs)


def _numeric(values, where: str, src: str, *, time: bool = False) -> np.ndarray:
    """The samples of a channel (TDMS) or variable (MAT) as float64, or an InputError naming it.

    Floating point is read as it is, and so are integers (int16 is a common DAQ type: a
    scaled TDMS channel comes out of npTDMS in its unit; an unscaled one holds whole numbers
    of its unit, and raw ADC codes far beyond the sensor's range are refused by the analysis,
    which knows the range). A time channel of TDMS time stamps becomes seconds from its first
    sample. Text, booleans and complex numbers are refused.
    """
    a = np.asarray(values)
    kind = a.dtype.kind
    if kind in "fiu":
        return a.astype(np.float64).ravel()
    if kind == "M" and time and a.size:
        return ((a - a.ravel()[0]) / np.timedelta64(1, "ns")).astype(np.float64).ravel() * 1e-9
    if kind == "O" and a.size and all(isinstance(x, (str, bytes)) for x in a.ravel()[:1000]):
        kind = "U"
    what = {
        "U": "text",
        "S": "text",
        "O": "mixed values",
        "b": "booleans (a digital line?)",
        "c": "complex numbers",
        "M": "dates",
        "m": "time spans",
    }.get(kind, f"values of type {a.dtype}")
    sample = ""
    if kind in "USO" and a.size:
        sample = f" (first: {str(a.ravel()[0])[:40]!r})"
    raise InputError(f"{where} holds {what}{sample}, expected numbers", source=src)


def _number(value, where: str, unit: str, src: str) -> float:
    """A scalar property or variable as a finite float, or an InputError naming it."""
    a = np.asarray(value)
    if a.dtype.kind in "USO" and a.size == 1:
        try:
            return _finite(float(str(a.ravel()[0]).strip()), where, unit, src)
        except ValueError:
            pass
        raise InputError(f"{where} = {str(a.ravel()[0])[:40]!r} is not a number of {unit}", source=src)
    if a.dtype.kind not in "fiu" or a.size != 1:
        shape = f"{a.size} values" if a.dtype.kind in "fiu" else f"a {a.dtype} value"
        raise InputError(f"{where} holds {shape}; expected one number of {unit}", source=src)
    return _finite(float(a.ravel()[0]), where, unit, src)


def _finite(v: float, where: str, unit: str, src: str) -> float:
    if not np.isfinite(v):
        raise InputError(f"{where} = {v!r} is not a finite number of {unit}", source=src)
    return v


def _rate(fs: float, where: str, src: str) -> float:
    try:
        return check_sample_rate(fs, where)
    except ValueError as e:
        raise InputError(str(e), source=src) from None


def _finish(
    src: str,
    cmap: ChannelMap,
    t: np.ndarray | None,
    disp: np.ndarray,
    load: np.ndarray | None,
    meta: dict,
    fs: float | None,
    where: str,
) -> Recording:
    if disp.size == 0:
        raise InputError(f"channel {cmap.displacement!r} is empty", source=src)
    if t is None:
        t = _time_from_rate(disp.size, cmap.sample_rate_hz or fs, src, where)
    unit = load_unit_from_name(cmap.load) if load is not None else None
    return Recording(
        source=src,
        time_s=t,
        displacement_v=disp,
        load=load,
        load_unit=unit,
        load_name=cmap.load if load is not None else None,
        meta={**meta, "displacement_channel": cmap.displacement},
    )


#: Load channel names looked for, in order, when the channel map keeps the default: the
#: unit is read from the suffix (load cell in kgf, N, or volts with --load-n-per-v).
DEFAULT_LOAD_NAMES = ("load_kgf", "load_n", "force_n", "load_v")


def _load_names(cmap: ChannelMap) -> tuple[str, ...]:
    if cmap.load is None:
        return ()
    if cmap.load_required or cmap.load != ChannelMap().load:
        return (cmap.load,)
    return DEFAULT_LOAD_NAMES


def _with_load(cmap: ChannelMap, name: str | None) -> ChannelMap:
    """The channel map naming the load channel that was found (its suffix gives the unit)."""
    return dataclasses.replace(cmap, load=name) if name is not None and name != cmap.load else cmap


def _find_load(cmap: ChannelMap, lookup):
    """The load channel found by ``lookup(name, required)``, and the channel map naming it."""
    for name in _load_names(cmap):
        found = lookup(name, cmap.load_required)
        if found is not None:
            return found, _with_load(cmap, name)
    return None, cmap


def _read_csv(path: Path, cmap: ChannelMap) -> Recording:
    src = str(path)
    required = [cmap.displacement]
    optional: list[str] = []
    if cmap.time is not None:
        (required if cmap.time_required else optional).append(cmap.time)
    loads = _load_names(cmap)
    (required if cmap.load_required else optional).extend(loads)
    tab = read_csv_columns(path, required, optional, allow_nan=True)
    cols = tab.columns
    cmap = _with_load(cmap, next((n for n in loads if n.strip().lower() in cols), None))

    def get(name: str | None) -> np.ndarray | None:
        return None if name is None else cols.get(name.strip().lower())

    t = get(cmap.time)
    if t is not None and not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(f"line {tab.lines[k]}, column {cmap.time!r}: empty or not a finite time", source=src)
    where = f"no column {cmap.time!r}" if cmap.time else "time=none"
    return _finish(src, cmap, t, get(cmap.displacement), get(cmap.load), {"format": "csv"}, None, where)


class _NptdmsMessages(logging.Filter):
    """Collects what npTDMS logs instead of letting it print to stderr.

    npTDMS prints its own ``[nptdms.reader WARNING] ...`` lines on a damaged or truncated
    file (and reads what it can); stiffmap says it once instead, as one warning naming the
    file (or not at all when the file is refused with an error anyway).
    """

    def __init__(self) -> None:
        super().__init__()
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        self.messages.append(record.getMessage())
        return False


@contextlib.contextmanager
def _quiet_nptdms(src: str):
    from nptdms.log import log_manager

    f = _NptdmsMessages()
    handler = log_manager.console_handler
    handler.addFilter(f)
    try:
        yield
    finally:
        handler.removeFilter(f)
    if f.messages:  # the file was read, but not cleanly
        first = re.sub(r"\s+", " ", f.messages[0])[:160]
        more = f" (and {len(f.messages) - 1} more)" if len(f.messages) > 1 else ""
        warnings.warn(
            f"{src}: npTDMS: {first}{more}: a damaged or truncated file? Its samples were read "
            "as far as they go; check the results",
            StiffmapWarning,
            stacklevel=3,
        )


def _read_tdms(path: Path, cmap: ChannelMap) -> Recording:
    with _quiet_nptdms(str(path)):
        return _read_tdms_quietly(path, cmap)


def _read_tdms_quietly(path: Path, cmap: ChannelMap) -> Recording:
    from nptdms import TdmsFile

    src = str(path)
    try:
        f = TdmsFile.read(path)
    except Exception as e:  # npTDMS raises ValueError, KeyError, struct.error... on a bad file
        raise InputError(f"not a readable TDMS file ({type(e).__name__}: {e})", source=src) from None
    groups = f.groups()
    if cmap.group is not None:
        names = [g.name for g in groups]
        if cmap.group not in names:
            raise InputError(
                f"no TDMS group {cmap.group!r} (groups: {', '.join(map(repr, names))})", source=src
            )
        groups = [f[cmap.group]]

    def find(name: str | None, required: bool):
        if name is None:
            return None
        hits = [(g, c) for g in groups for c in g.channels() if c.name == name]
        if not hits:
            hits = [(g, c) for g in groups for c in g.channels() if c.name.lower() == name.lower()]
        if len(hits) > 1:
            raise FieldError(
                "channel_map",
                f"channel {name!r} is in several groups ({', '.join(repr(g.name) for g, _ in hits)}); "
                "choose one with {channel_map} group=NAME",
                source=src,
            )
        if not hits:
            if required:
                have = [f"{g.name}/{c.name}" for g in groups for c in g.channels()]
                raise InputError(
                    f"no channel {name!r} (channels: {', '.join(map(repr, have)) or 'none'})", source=src
                )
            return None
        return hits[0][1]

    def data(ch, **kw) -> np.ndarray:
        try:
            raw = ch[:]
        except Exception as e:  # npTDMS on a damaged data block: ValueError, struct.error, ...
            raise InputError(
                f"channel {ch.name!r}: cannot read its samples ({type(e).__name__}: {e})", source=src
            ) from None
        return _numeric(raw, f"channel {ch.name!r}", src, **kw)

    dch = find(cmap.displacement, True)
    tch = find(cmap.time, cmap.time_required)
    lch, cmap = _find_load(cmap, find)
    disp = data(dch)
    meta = {"format": "tdms", "properties": {k: str(v) for k, v in dch.properties.items()}}
    t = None
    if tch is not None:
        t = data(tch, time=True)
        if t.size != disp.size:
            raise InputError(
                f"time channel {tch.name!r} has {t.size} samples, {dch.name!r} has {disp.size}", source=src
            )
    elif "wf_increment" in dch.properties:
        where = f"channel {dch.name!r}: property wf_increment"
        inc = _number(dch.properties["wf_increment"], where, "s", src)
        if not inc > 0:
            raise InputError(f"{where} = {inc!r}, expected > 0 s", source=src)
        _rate(1.0 / inc, f"{where} = {inc:g} s", src)
        off = _number(
            dch.properties.get("wf_start_offset", 0.0),
            f"channel {dch.name!r}: property wf_start_offset",
            "s",
            src,
        )
        t = off + np.arange(disp.size) * inc
    load = None if lch is None else data(lch)
    if load is not None and load.size != disp.size:
        raise InputError(
            f"load channel {lch.name!r} has {load.size} samples, {dch.name!r} has {disp.size}", source=src
        )
    where = "no time channel and no wf_increment property"
    return _finish(src, cmap, t, disp, load, meta, None, where)


def _mat_vector(x, name: str, src: str, *, time: bool = False) -> np.ndarray:
    a = np.asarray(x)
    if a.ndim > 1 and sum(s > 1 for s in a.shape) > 1:
        raise InputError(f"variable {name!r} has shape {a.shape}; expected a vector", source=src)
    # MATLAB char arrays and cells come as text or objects, logicals as booleans: refused there.
    return _numeric(a, f"variable {name!r}", src, time=time)


def _read_mat(path: Path, cmap: ChannelMap) -> Recording:
    import scipy.io

    src = str(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", source=src) from None
    # Only the variables a recording needs are read (by any case of their names); in a v5 to v7
    # file they are checked first by mat5_variables (SciPy crashes on some damaged files).
    wanted = {n.lower() for n in (cmap.displacement, cmap.time, cmap.group, "sample_rate_hz", "fs") if n}
    wanted |= {n.lower() for n in _load_names(cmap)}
    names = listing = None
    try:
        version = scipy.io.matlab.matfile_version(io.BytesIO(data))[0]
    except Exception:  # too short, unknown version: loadmat says it in its words below
        version = None
    if version == 1:
        found = mat5_variables(data, lambda name: name.lower() in wanted, src)
        names = [v.name for v in found if v.name.lower() in wanted]
        listing = sorted(v.name for v in found)
    try:
        mat = scipy.io.loadmat(
            io.BytesIO(data), squeeze_me=True, struct_as_record=False, variable_names=names
        )
    except NotImplementedError:
        raise InputError(
            "MATLAB v7.3 (HDF5) file; save it with save(..., '-v7') so SciPy can read it", source=src
        ) from None
    except Exception as e:  # scipy raises ValueError, TypeError... on a bad file
        raise InputError(f"not a readable MATLAB .mat file ({type(e).__name__}: {e})", source=src) from None
    space: dict = {k: v for k, v in mat.items() if not k.startswith("__")}
    if listing is None:
        listing = sorted(space)
    if cmap.group is not None:
        if cmap.group not in space:
            raise InputError(f"no variable {cmap.group!r} (variables: {', '.join(listing)})", source=src)
        st = space[cmap.group]
        if not hasattr(st, "_fieldnames"):
            raise InputError(f"variable {cmap.group!r} is not a struct", source=src)
        space = {k: getattr(st, k) for k in st._fieldnames}
        listing = sorted(space)

    def get(name: str | None, required: bool, **kw) -> np.ndarray | None:
        if name is None:
            return None
        key = name if name in space else next((k for k in space if k.lower() == name.lower()), None)
        if key is None:
            if required:
                raise InputError(f"no variable {name!r} (variables: {', '.join(listing)})", source=src)
            return None
        return _mat_vector(space[key], key, src, **kw)

    disp = get(cmap.displacement, True)
    t = get(cmap.time, cmap.time_required)
    load, cmap = _find_load(cmap, get)
    fs = None
    if t is None and cmap.sample_rate_hz is None:  # the time comes from a sample rate variable
        for k in ("sample_rate_hz", "fs"):
            if k in space:
                where = f"variable {k!r}"
                fs = _rate(_number(space[k], where, "Hz", src), where, src)
                break
    for name, arr in ((cmap.time, t), (cmap.load, load)):
        if arr is not None and arr.size != disp.size:
            raise InputError(
                f"variable {name!r} has {arr.size} samples, {cmap.displacement!r} has {disp.size}", source=src
            )
    return _finish(src, cmap, t, disp, load, {"format": "mat"}, fs, "no time variable and no sample_rate_hz")


def read_recording(path: str | os.PathLike, channel_map: ChannelMap | None = None) -> Recording:
    """Read one DAQ recording (CSV, TDMS or MAT by suffix).

    Parameters
    ----------
    path : path-like
    channel_map : ChannelMap, optional
        Default: columns ``time_s``, ``displacement_v``, ``load_kgf`` (load optional).

    Returns
    -------
    Recording
        Raw values, volts and the load channel's own unit; NaN marks missing samples.

    Raises
    ------
    InputError
        Missing file, unknown format, missing channel, bad values; the message names
        the file and the channel.
    """
    cmap = channel_map or ChannelMap()
    p = Path(path)
    fmt = format_from_path(p)
    if not p.exists():
        raise InputError("file not found", source=str(path))
    if p.is_dir():
        raise InputError("is a directory, expected a recording file", source=str(path))
    return {"csv": _read_csv, "tdms": _read_tdms, "mat": _read_mat}[fmt](p, cmap)


def _columns(rec: Recording) -> tuple[str, str | None]:
    load_name = None
    if rec.load is not None:
        load_name = rec.load_name or f"load_{(rec.load_unit or 'kgf').lower()}"
    return "displacement_v", load_name


def _uniform(t: np.ndarray) -> bool:
    """True when ``t`` is exactly ``t[0] + i * (t[1] - t[0])`` (a waveform)."""
    return bool(np.array_equal(t, t[0] + np.arange(t.size) * (t[1] - t[0])))


def write_recording(
    recording: Recording, path: str | os.PathLike, fmt: str | None = None, *, group: str = "daq"
) -> Path:
    """Write a recording as CSV, TDMS or MAT, readable back with the default channel map.

    Columns/channels/variables: ``time_s`` (TDMS: waveform properties instead when
    the sampling is uniform), ``displacement_v`` and, when there is a load,
    ``recording.load_name`` (default ``load_kgf`` / ``load_n``). Values are written
    at full float64 precision, so every format reads back bit for bit.

    Parameters
    ----------
    recording : Recording
    path : path-like
    fmt : {"csv", "tdms", "mat"}, optional
        Default: from the suffix.
    group : str
        TDMS group name.

    Returns
    -------
    Path
        The path written.
    """
    p = Path(path)
    fmt = fmt or format_from_path(p)
    dname, lname = _columns(recording)
    t = recording.time_s
    cols = {"time_s": t, dname: recording.displacement_v}
    if lname is not None:
        cols[lname] = recording.load
    if fmt == "csv":
        data = np.column_stack(list(cols.values()))
        buf = io.StringIO()
        buf.write(",".join(cols) + "\n")
        np.savetxt(buf, data, fmt="%.17g", delimiter=",")
        atomic_write_text(p, buf.getvalue())
    elif fmt == "tdms":
        from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

        objs = [RootObject({"source": recording.source}), GroupObject(group)]
        wave = _uniform(t)
        props = {"wf_start_offset": float(t[0]), "wf_increment": float(t[1] - t[0])} if wave else {}
        if not wave:
            objs.append(ChannelObject(group, "time_s", t, {"unit_string": "s"}))
        objs.append(ChannelObject(group, dname, recording.displacement_v, {**props, "unit_string": "V"}))
        if lname is not None:
            objs.append(ChannelObject(group, lname, recording.load, dict(props)))
        buf = io.BytesIO()
        with TdmsWriter(buf) as w:
            w.write_segment(objs)
        atomic_write_bytes(p, buf.getvalue())
    elif fmt == "mat":
        import scipy.io

        buf = io.BytesIO()
        scipy.io.savemat(buf, {k: v.reshape(-1, 1) for k, v in cols.items()}, oned_as="column")
        atomic_write_bytes(p, _fixed_mat_header(buf.getvalue()))
    else:
        raise ValueError(f"fmt must be 'csv', 'tdms' or 'mat', got {fmt!r}")
    return p


def _fixed_mat_header(data: bytes) -> bytes:
    """A MAT 5 file with its 116-byte descriptive text fixed (SciPy writes the time of day there):
    the same recording gives the same bytes, as ``simulate``'s seed promises."""
    text = b"MATLAB 5.0 MAT-file, written by stiffmap"
    return text.ljust(116, b" ") + data[116:]
