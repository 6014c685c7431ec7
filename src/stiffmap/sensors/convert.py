"""Volts to displacement, load to newtons, and the samples that cannot be trusted.

A displacement sensor behind a DAQ gives volts; the displacement along the
sensor's axis is ``axis_sign * scale_um_per_v * volts`` (µm; a mirror in the beam
path flips the sign, ``axis_sign = -1``). The analog output is limited to
``+-range_v``: a sample at the limit is *saturated* (its true value is beyond the
limit), a sample beyond it is *out of range* (wrong scale or range given, or an
overload). A NaN sample or a gap in the time stamps is a *dropout*. Every such
sample is flagged and grouped into time spans for messages; none is used silently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..units import G_REFERENCE_PAPER, newton_from_kgf

__all__ = [
    "SampleSpan",
    "Conversion",
    "spans_from_mask",
    "displacement_from_volts",
    "newton_from_load",
    "time_gaps",
    "describe_spans",
]

#: A time step longer than this many median steps is a gap (missing samples).
GAP_FACTOR = 1.5


@dataclass(frozen=True)
class SampleSpan:
    """A run of flagged samples.

    Attributes
    ----------
    kind : str
        ``"saturated"``, ``"out of range"`` or ``"dropout"``.
    start, stop : int
        Sample indices, ``[start, stop)``; for a time gap, the two samples around it.
    t_start_s, t_end_s : float
        Time of the first and last flagged sample (of the samples around a gap), s.
    """

    kind: str
    start: int
    stop: int
    t_start_s: float
    t_end_s: float

    @property
    def n(self) -> int:
        return self.stop - self.start

    def describe(self) -> str:
        return f"{self.kind} from {self.t_start_s:.3f} s to {self.t_end_s:.3f} s"


def spans_from_mask(mask) -> np.ndarray:
    """Runs of True in a boolean vector.

    Parameters
    ----------
    mask : array_like of bool, shape (n,)

    Returns
    -------
    ndarray of int, shape (k, 2)
        ``[start, stop)`` of each run, in order.
    """
    m = np.asarray(mask, dtype=bool).ravel()
    if m.size == 0:
        return np.zeros((0, 2), dtype=int)
    d = np.diff(np.concatenate([[0], m.view(np.int8), [0]]))
    return np.column_stack([np.flatnonzero(d == 1), np.flatnonzero(d == -1)])


def _spans(kind: str, mask: np.ndarray, t: np.ndarray) -> list[SampleSpan]:
    return [SampleSpan(kind, int(a), int(b), float(t[a]), float(t[b - 1])) for a, b in spans_from_mask(mask)]


def time_gaps(time_s) -> list[SampleSpan]:
    """Gaps in the time stamps: steps longer than ``GAP_FACTOR`` times the median step.

    Parameters
    ----------
    time_s : array_like, shape (n,), s, increasing

    Returns
    -------
    list of SampleSpan
        ``kind="dropout"``, ``[start, stop)`` = the two samples around the gap.
    """
    t = np.asarray(time_s, dtype=np.float64)
    dt = np.diff(t)
    if dt.size == 0:
        return []
    big = np.flatnonzero(dt > GAP_FACTOR * np.median(dt))
    return [SampleSpan("dropout", int(i), int(i) + 2, float(t[i]), float(t[i + 1])) for i in big]


def describe_spans(spans, limit: int = 3) -> str:
    """``saturated from 1.000 s to 1.200 s; dropout from ...`` (at most ``limit``, then a count)."""
    spans = list(spans)
    text = "; ".join(s.describe() for s in spans[:limit])
    if len(spans) > limit:
        text += f"; and {len(spans) - limit} more span(s)"
    return text


@dataclass(frozen=True)
class Conversion:
    """Displacement from volts, with the flags of each sample.

    Attributes
    ----------
    displacement_mm : ndarray, shape (n,), mm
        Along the sensor axis, sign applied; NaN where the sample is missing.
    saturated, out_of_range, missing : ndarray of bool, shape (n,)
    spans : tuple of SampleSpan
        Runs of flagged samples, in time order.
    """

    displacement_mm: np.ndarray
    saturated: np.ndarray
    out_of_range: np.ndarray
    missing: np.ndarray
    spans: tuple[SampleSpan, ...]

    @property
    def bad(self) -> np.ndarray:
        """Samples that cannot be used, shape (n,)."""
        return self.saturated | self.out_of_range | self.missing


def displacement_from_volts(
    volts,
    time_s,
    *,
    scale_um_per_v: float = 640.0,
    range_v: float = 8.0,
    axis_sign: float = 1.0,
    saturation_margin_v: float = 0.01,
) -> Conversion:
    """Convert a displacement sensor's output to mm and flag the samples not to trust.

    Parameters
    ----------
    volts : array_like, shape (n,), V
        NaN marks a missing sample.
    time_s : array_like, shape (n,), s
        Only for the time spans of the flags.
    scale_um_per_v : float
        Sensor scale, µm/V (the milling study's LDV: 640 µm/V).
    range_v : float
        Analog output limit, V (the study's LDV: +-8 V, 16 V peak to peak).
    axis_sign : {+1, -1}
        -1 when a mirror flips the beam (the study's horizontal measurements).
    saturation_margin_v : float
        A sample with ``|v| >= range_v - margin`` is saturated; ``|v| > range_v +
        margin`` is out of range.

    Returns
    -------
    Conversion
    """
    v = np.asarray(volts, dtype=np.float64).ravel()
    t = np.asarray(time_s, dtype=np.float64).ravel()
    if v.shape != t.shape:
        raise ValueError(f"volts and time_s must have the same shape, got {v.shape} and {t.shape}")
    for name, x in (("scale_um_per_v", scale_um_per_v), ("range_v", range_v)):
        if not (math.isfinite(x) and x > 0):
            raise ValueError(f"{name} must be a positive number, got {x!r}")
    if axis_sign not in (1, -1):
        raise ValueError(f"axis_sign must be +1 or -1, got {axis_sign!r}")
    if not (math.isfinite(saturation_margin_v) and 0 <= saturation_margin_v < range_v):
        raise ValueError(f"saturation_margin_v must be in [0, range_v), got {saturation_margin_v!r}")
    missing = ~np.isfinite(v)
    a = np.abs(np.where(missing, 0.0, v))
    out = a > range_v + saturation_margin_v
    sat = (a >= range_v - saturation_margin_v) & ~out
    disp = axis_sign * scale_um_per_v * 1e-3 * v
    spans = _spans("saturated", sat, t) + _spans("out of range", out, t) + _spans("dropout", missing, t)
    spans.sort(key=lambda s: s.start)
    return Conversion(disp, sat, out, missing, tuple(spans))


def newton_from_load(
    values, unit: str, *, g: float = G_REFERENCE_PAPER, n_per_v: float | None = None
) -> np.ndarray:
    """Load values (kgf, N, or volts of a load cell) in N.

    Parameters
    ----------
    values : array_like, kgf, N or V
    unit : {"kgf", "N", "V"}
    g : float
        m/s^2 for kgf (default 9.81, the milling study's: 50 kgf = 490.5 N).
    n_per_v : float, optional
        Load-cell scale for ``unit="V"``, N/V.

    Returns
    -------
    ndarray, N
    """
    x = np.asarray(values, dtype=np.float64)
    if unit == "kgf":
        return x * newton_from_kgf(1.0, g)
    if unit == "N":
        return x.copy()
    if unit == "V":
        if n_per_v is None or not (math.isfinite(n_per_v) and n_per_v != 0):
            raise ValueError(
                f"a load channel in volts needs a non-zero load-cell scale n_per_v, got {n_per_v!r}"
            )
        return x * float(n_per_v)
    raise ValueError(f"unit must be 'kgf', 'N' or 'V', got {unit!r}")
