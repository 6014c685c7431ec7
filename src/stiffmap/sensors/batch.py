"""Many recordings: per-file results, and per-point static errors for maps and model fits.

The milling study measured, at each of several points of the workspace, one
recording with a horizontal load (through a mirror) and one with a vertical load.
:func:`static_errors_from_files` takes such a list of (point, direction, file)
and returns a :class:`StaticErrorSet`: one static error per entry (NaN and a
reason where the recording could not be used), ready to draw over the workspace
and to fit a mechanism model (its :meth:`~StaticErrorSet.observations` are the
(pose, force, measurement direction, value, standard error) of
:mod:`stiffmap.models`' static-error fit).

An index CSV lists the entries of a campaign: columns ``x, y[, z]`` (mm), the
direction as ``direction`` (``x``, ``-y``...) or as ``ux, uy[, uz]``, ``file``
(relative to the index's folder) and optionally ``axis_sign`` (-1 behind a mirror).

:func:`analyse_batch` does both at once, as ``stiffmap sensor`` does: recordings
given one by one and the entries of an index.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FieldError, InputError
from ..io import ALLOW_OUTSIDE_OPTION, leaves_directory, read_csv_columns
from ..stiffness import MAX_POSITION_MM
from .analysis import SensorConfig, SensorResult, analyse_recording
from .io import format_from_path, read_recording
from .recording import ChannelMap

__all__ = [
    "MeasurementEntry",
    "StaticErrorSet",
    "SensorBatch",
    "analyse_batch",
    "analyse_files",
    "static_errors_from_files",
    "read_measurement_index",
    "direction_from",
]

_AXES = "xyz"


def direction_from(value, dim: int) -> np.ndarray:
    """A unit direction from ``"x"``, ``"-y"``... or a vector.

    Parameters
    ----------
    value : str or array_like, shape (dim,)
    dim : {2, 3}

    Returns
    -------
    ndarray, shape (dim,)
    """
    if isinstance(value, str):
        s = value.strip().lower()
        sign = -1.0 if s.startswith("-") else 1.0
        ax = s.lstrip("+-")
        if ax not in _AXES[:dim]:
            raise ValueError(
                f"direction must be one of {', '.join(_AXES[:dim])} (optionally signed), got {value!r}"
            )
        u = np.zeros(dim)
        u[_AXES.index(ax)] = sign
        return u
    u = np.asarray(value, dtype=np.float64).ravel()
    if u.shape != (dim,) or not np.all(np.isfinite(u)) or not np.any(u):
        raise ValueError(f"direction must be a finite non-zero vector of {dim} components, got {value!r}")
    big = float(np.abs(u).max())
    if not 1e-150 < big < 1e150:  # the norm of huge components would overflow, of tiny ones underflow
        u = u / big
    return u / np.linalg.norm(u)


@dataclass(frozen=True)
class MeasurementEntry:
    """One recording of a campaign.

    Attributes
    ----------
    point : ndarray, shape (d,), mm
        Where the tool was (d = 2 for a planar mechanism, 3 otherwise).
    direction : ndarray, shape (d,)
        Unit direction of the load and of the measured displacement, base frame.
    file : str
    axis_sign : int or None
        -1 behind a mirror; None: the configuration's.
    origin : str
        Where the entry was listed (``index.csv, line 3``), said when its recording fails.
    """

    point: np.ndarray
    direction: np.ndarray
    file: str
    axis_sign: int | None = None
    origin: str = ""

    def __post_init__(self) -> None:
        p = np.asarray(self.point, dtype=np.float64).ravel()
        if p.size not in (2, 3) or not np.all(np.isfinite(p)):
            raise ValueError(f"point must be 2 or 3 finite coordinates (mm), got {self.point!r}")
        object.__setattr__(self, "point", p)
        object.__setattr__(self, "direction", direction_from(self.direction, p.size))
        if self.axis_sign not in (None, 1, -1):
            raise ValueError(f"axis_sign must be +1, -1 or None, got {self.axis_sign!r}")


def _entry(e) -> MeasurementEntry:
    if isinstance(e, MeasurementEntry):
        return e
    if isinstance(e, Sequence) and len(e) in (3, 4):
        return MeasurementEntry(*e)
    raise ValueError(
        f"an entry must be a MeasurementEntry or (point, direction, file[, axis_sign]), got {e!r}"
    )


def _worded(e: InputError, names: Mapping[str, str] | None) -> InputError:
    """``e`` with a :class:`~stiffmap.errors.FieldError`'s fields named as the caller names them."""
    return e.worded(names) if names and isinstance(e, FieldError) else e


def analyse_files(
    files: Iterable[str | os.PathLike],
    channel_map: ChannelMap | None = None,
    config: SensorConfig | None = None,
    names: Mapping[str, str] | None = None,
) -> list[SensorResult | InputError]:
    """Read and analyse each file; a bad file gives its InputError in its place, the others go on.

    ``names`` words the fields of a :class:`~stiffmap.errors.FieldError` (``load_unit``) as
    the caller names them (``--load-unit``, ``sensor.load_unit``).
    """
    out: list[SensorResult | InputError] = []
    for f in files:
        try:
            out.append(analyse_recording(read_recording(f, channel_map), config))
        except InputError as e:
            out.append(_worded(e, names).with_source(str(f)))
    return out


@dataclass(frozen=True)
class StaticErrorSet:
    """Static errors of a set of (point, direction) recordings.

    Attributes
    ----------
    points : ndarray, shape (m, d), mm
    directions : ndarray, shape (m, d)
        Unit direction of the load and of the measurement.
    files : tuple of str
    reference_load_n : float
    static_error_mm, static_error_std_mm : ndarray, shape (m,)
        Displacement along the direction under ``reference_load_n`` along it, and its
        standard error, mm; NaN exactly where ``valid`` is False (the std is also NaN
        when a recording had only two plateaus).
    stiffness_n_per_mm, stiffness_std_n_per_mm : ndarray, shape (m,)
    valid : ndarray of bool, shape (m,)
    reasons : tuple of str
        Why an entry is not valid ("" when valid).
    results : tuple of SensorResult or None
    """

    points: np.ndarray
    directions: np.ndarray
    files: tuple[str, ...]
    reference_load_n: float
    static_error_mm: np.ndarray
    static_error_std_mm: np.ndarray
    stiffness_n_per_mm: np.ndarray
    stiffness_std_n_per_mm: np.ndarray
    valid: np.ndarray
    reasons: tuple[str, ...]
    results: tuple[SensorResult | None, ...]

    @property
    def force_n(self) -> np.ndarray:
        """The reference force vector of each entry, shape (m, d), N."""
        return self.reference_load_n * self.directions

    def observations(self) -> dict[str, np.ndarray]:
        """The valid entries as static-error observations for a model fit.

        Returns
        -------
        dict
            ``points`` (k, d) mm, ``force_n`` (k, d) N, ``direction`` (k, d) unit,
            ``value_mm`` (k,), ``std_mm`` (k,) (NaN where a recording had two plateaus).
        """
        v = self.valid
        return {
            "points": self.points[v],
            "force_n": self.force_n[v],
            "direction": self.directions[v],
            "value_mm": self.static_error_mm[v],
            "std_mm": self.static_error_std_mm[v],
        }

    def to_rows(self) -> list[dict]:
        """One dict per entry (µm for the static error), for JSON or CSV."""
        d = self.points.shape[1]
        rows = []
        for i in range(self.points.shape[0]):
            row = {a: float(self.points[i, j]) for j, a in enumerate(_AXES[:d])}
            row.update({f"u{a}": float(self.directions[i, j]) for j, a in enumerate(_AXES[:d])})
            row.update(
                {
                    "file": self.files[i],
                    "static_error_um": 1e3 * self.static_error_mm[i],
                    "static_error_std_um": 1e3 * self.static_error_std_mm[i],
                    "stiffness_n_per_mm": self.stiffness_n_per_mm[i],
                    "stiffness_std_n_per_mm": self.stiffness_std_n_per_mm[i],
                    "valid": bool(self.valid[i]),
                    "error": self.reasons[i] or None,
                    "flags": list(self.results[i].flags) if self.results[i] is not None else [],
                }
            )
            rows.append(row)
        return rows


def static_errors_from_files(
    entries: Iterable,
    channel_map: ChannelMap | None = None,
    config: SensorConfig | None = None,
    names: Mapping[str, str] | None = None,
) -> StaticErrorSet:
    """Static error at each (point, direction) from its recording.

    Parameters
    ----------
    entries : iterable of MeasurementEntry or (point, direction, file[, axis_sign])
        All points of the same dimension (2 or 3).
    channel_map : ChannelMap, optional
    config : SensorConfig, optional
        Shared by all recordings; an entry's ``axis_sign`` overrides the config's.
    names : mapping of str to str, optional
        As :func:`analyse_files`.

    Returns
    -------
    StaticErrorSet
        Entries whose recording fails are kept, with NaN values, ``valid`` False and
        the error message in ``reasons``.
    """
    ents = [_entry(e) for e in entries]
    if not ents:
        raise ValueError("no entries")
    dims = {e.point.size for e in ents}
    if len(dims) > 1:
        raise ValueError(f"all points must have the same dimension, got {sorted(dims)}")
    cfg = config or SensorConfig()
    m = len(ents)
    vals = np.full((4, m), np.nan)
    valid = np.zeros(m, dtype=bool)
    reasons, results = [], []
    for i, e in enumerate(ents):
        c = cfg if e.axis_sign is None else dataclasses.replace(cfg, axis_sign=e.axis_sign)
        try:
            r = analyse_recording(read_recording(e.file, channel_map), c)
        except InputError as err:
            reason = str(_worded(err, names).with_source(str(e.file)))
            reasons.append(f"{reason} (listed in {e.origin})" if e.origin else reason)
            results.append(None)
            continue
        vals[:, i] = (
            r.static_error_mm,
            r.static_error_std_mm,
            r.fit.stiffness_n_per_mm,
            r.fit.stiffness_std_n_per_mm,
        )
        valid[i] = math.isfinite(r.static_error_mm)
        reasons.append("" if valid[i] else "static error is not finite")
        results.append(r)
    return StaticErrorSet(
        points=np.stack([e.point for e in ents]),
        directions=np.stack([e.direction for e in ents]),
        files=tuple(str(e.file) for e in ents),
        reference_load_n=cfg.reference_load_n,
        static_error_mm=vals[0],
        static_error_std_mm=vals[1],
        stiffness_n_per_mm=vals[2],
        stiffness_std_n_per_mm=vals[3],
        valid=valid,
        reasons=tuple(reasons),
        results=tuple(results),
    )


@dataclass(frozen=True)
class SensorBatch:
    """Recordings analysed one by one and, with an index, the static error per point.

    Attributes
    ----------
    files : tuple of str
        The recordings given one by one.
    results : tuple of SensorResult or InputError
        The analysis of each; a recording that could not be used gives its error.
    static_errors : StaticErrorSet or None
        The index's entries, when an index was given.
    """

    files: tuple[str, ...]
    results: tuple[SensorResult | InputError, ...]
    static_errors: StaticErrorSet | None

    @property
    def n_ok(self) -> int:
        """Recordings analysed plus valid index entries."""
        n = sum(not isinstance(r, InputError) for r in self.results)
        return n + (int(self.static_errors.valid.sum()) if self.static_errors is not None else 0)

    @property
    def n_failed(self) -> int:
        """Recordings that could not be used plus invalid index entries."""
        n = sum(isinstance(r, InputError) for r in self.results)
        return n + (int((~self.static_errors.valid).sum()) if self.static_errors is not None else 0)

    def recording_rows(self) -> list[dict]:
        """One dict per recording: its result (``SensorResult.to_dict``) or its ``file`` and ``error``."""
        return [
            {"file": f, "error": str(r)} if isinstance(r, InputError) else r.to_dict()
            for f, r in zip(self.files, self.results, strict=True)
        ]

    def to_json(self) -> list[dict] | dict:
        """The recordings' rows; with an index its rows (``StaticErrorSet.to_rows``), under
        ``points`` beside ``recordings`` when there are both."""
        if self.static_errors is None:
            return self.recording_rows()
        points = self.static_errors.to_rows()
        return points if not self.files else {"recordings": self.recording_rows(), "points": points}


def analyse_batch(
    files: Sequence[str | os.PathLike],
    entries: Iterable | None = None,
    channel_map: ChannelMap | None = None,
    config: SensorConfig | None = None,
    names: Mapping[str, str] | None = None,
) -> SensorBatch:
    """Analyse recordings one by one (:func:`analyse_files`) and the entries of an index.

    Parameters
    ----------
    files : sequence of path-like
        Recordings analysed one by one (may be empty).
    entries : iterable of MeasurementEntry, optional
        An index's entries (:func:`read_measurement_index`): their static errors
        (:func:`static_errors_from_files`). None: no index.
    channel_map : ChannelMap, optional
    config : SensorConfig, optional
        Shared by all recordings.
    names : mapping of str to str, optional
        How the caller names the analysis' fields in messages (:func:`analyse_files`).
    """
    results = analyse_files(files, channel_map, config, names) if files else []
    ses = static_errors_from_files(entries, channel_map, config, names) if entries is not None else None
    return SensorBatch(tuple(str(f) for f in files), tuple(results), ses)


def read_measurement_index(path: str | os.PathLike, *, allow_outside: bool = False) -> list[MeasurementEntry]:
    """Read an index CSV of a sensor campaign (see the module docstring).

    The recordings it names are relative to its folder and must stay inside it (after
    resolving ``..``, absolute paths and symbolic links) unless ``allow_outside``
    (``stiffmap sensor --allow-outside-paths``).

    Raises
    ------
    InputError
        Naming the index file and the line of a bad row (a recording named outside the
        index's folder: the line, the name and the option).
    """
    src = str(path)
    head = read_csv_columns(
        path,
        ["x", "y", "file"],
        ["z", "direction", "ux", "uy", "uz", "axis_sign"],
        text_columns=["file", "direction", "axis_sign"],
        allow_nan=True,
    )
    dim = 3 if head.has("z") else 2
    base = Path(path).parent
    use_vec = head.has("ux") and head.has("uy")
    if not use_vec and "direction" not in head.text:
        raise InputError("needs a column 'direction' (x, -y...) or columns ux, uy[, uz]", source=src)
    out = []
    for i, line in enumerate(head.lines):
        coords = [head.columns[a][i] for a in _AXES[:dim]]
        if not all(math.isfinite(c) for c in coords):
            raise InputError(f"line {line}: point coordinates must be numbers", source=src)
        if any(abs(c) > MAX_POSITION_MM for c in coords):
            raise InputError(
                f"line {line}: point ({', '.join(f'{c:.6g}' for c in coords)}) mm is beyond "
                f"+-{MAX_POSITION_MM:g} mm: not a plausible position",
                source=src,
            )
        try:
            if use_vec:
                uv = [head.columns[f"u{a}"][i] if head.has(f"u{a}") else 0.0 for a in _AXES[:dim]]
                u = direction_from(uv, dim)
            else:
                u = direction_from(head.text["direction"][i], dim)
        except ValueError as e:
            raise InputError(f"line {line}: {e}", source=src) from None
        f = head.text["file"][i]
        if not f:
            raise InputError(f"line {line}: empty 'file'", source=src)
        sign = None
        if "axis_sign" in head.text and head.text["axis_sign"][i].strip():
            s = head.text["axis_sign"][i].strip()
            if s not in ("1", "+1", "-1"):
                raise InputError(f"line {line}, column 'axis_sign': {s!r}, expected 1 or -1", source=src)
            sign = -1 if s == "-1" else 1
        how = None if allow_outside else leaves_directory(base, f)
        if how is not None:
            raise InputError(
                f"line {line}, column 'file': {f!r} {how}, outside the index's folder {base}; the "
                f"recordings an index names must stay inside it (give {ALLOW_OUTSIDE_OPTION} to read them "
                "anyway)",
                source=src,
            )
        fp = Path(f)
        try:
            format_from_path(fp)
        except InputError as e:
            raise InputError(f"line {line}, column 'file': {f!r}: {e.detail}", source=src) from None
        where = f"{src}, line {line}"
        out.append(
            MeasurementEntry(np.array(coords), u, str(fp if fp.is_absolute() else base / fp), sign, where)
        )
    return out
