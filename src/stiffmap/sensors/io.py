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

import dataclasses
import io
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_write_bytes, atomic_write_text, read_csv_columns
from .recording import ChannelMap, Recording, load_unit_from_name

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
        raise InputError(
            f"no time channel ({where}) and no sample rate; name the time column with "
            "--channel-map time=COL or give rate=HZ",
            source=src,
        )
    return np.arange(n) * (1.0 / fs)


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
        meta=meta,
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


def _read_tdms(path: Path, cmap: ChannelMap) -> Recording:
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
            raise InputError(
                f"channel {name!r} is in several groups ({', '.join(repr(g.name) for g, _ in hits)}); "
                "choose one with --channel-map group=NAME",
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

    dch = find(cmap.displacement, True)
    tch = find(cmap.time, cmap.time_required)
    lch, cmap = _find_load(cmap, find)
    disp = np.asarray(dch[:], dtype=np.float64)
    meta = {"format": "tdms", "properties": {k: str(v) for k, v in dch.properties.items()}}
    t = None
    if tch is not None:
        t = np.asarray(tch[:], dtype=np.float64)
        if t.size != disp.size:
            raise InputError(
                f"time channel {tch.name!r} has {t.size} samples, {dch.name!r} has {disp.size}", source=src
            )
    elif "wf_increment" in dch.properties:
        inc = float(dch.properties["wf_increment"])
        if not (np.isfinite(inc) and inc > 0):
            raise InputError(f"channel {dch.name!r}: wf_increment = {inc!r}, expected > 0 s", source=src)
        off = float(dch.properties.get("wf_start_offset", 0.0))
        t = off + np.arange(disp.size) * inc
    load = None if lch is None else np.asarray(lch[:], dtype=np.float64)
    if load is not None and load.size != disp.size:
        raise InputError(
            f"load channel {lch.name!r} has {load.size} samples, {dch.name!r} has {disp.size}", source=src
        )
    where = "no time channel and no wf_increment property"
    return _finish(src, cmap, t, disp, load, meta, None, where)


def _mat_vector(x, name: str, src: str) -> np.ndarray:
    a = np.asarray(x)
    if a.dtype.kind not in "fiub":
        raise InputError(f"variable {name!r} is not numeric (MATLAB class {a.dtype})", source=src)
    a = a.astype(np.float64)
    if a.ndim > 1 and sum(s > 1 for s in a.shape) > 1:
        raise InputError(f"variable {name!r} has shape {a.shape}; expected a vector", source=src)
    return a.ravel()


def _read_mat(path: Path, cmap: ChannelMap) -> Recording:
    import scipy.io

    src = str(path)
    try:
        mat = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except NotImplementedError:
        raise InputError(
            "MATLAB v7.3 (HDF5) file; save it with save(..., '-v7') so SciPy can read it", source=src
        ) from None
    except Exception as e:  # scipy raises ValueError, TypeError... on a bad file
        raise InputError(f"not a readable MATLAB .mat file ({type(e).__name__}: {e})", source=src) from None
    space: dict = {k: v for k, v in mat.items() if not k.startswith("__")}
    if cmap.group is not None:
        if cmap.group not in space:
            raise InputError(
                f"no variable {cmap.group!r} (variables: {', '.join(sorted(space))})", source=src
            )
        st = space[cmap.group]
        if not hasattr(st, "_fieldnames"):
            raise InputError(f"variable {cmap.group!r} is not a struct", source=src)
        space = {k: getattr(st, k) for k in st._fieldnames}

    def get(name: str | None, required: bool) -> np.ndarray | None:
        if name is None:
            return None
        key = name if name in space else next((k for k in space if k.lower() == name.lower()), None)
        if key is None:
            if required:
                raise InputError(f"no variable {name!r} (variables: {', '.join(sorted(space))})", source=src)
            return None
        return _mat_vector(space[key], key, src)

    disp = get(cmap.displacement, True)
    t = get(cmap.time, cmap.time_required)
    load, cmap = _find_load(cmap, get)
    fs = None
    for k in ("sample_rate_hz", "fs"):
        if k in space and np.size(space[k]) == 1:
            fs = float(np.asarray(space[k], dtype=np.float64).ravel()[0])
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
        atomic_write_bytes(p, buf.getvalue())
    else:
        raise ValueError(f"fmt must be 'csv', 'tdms' or 'mat', got {fmt!r}")
    return p
