"""One recording to plateaus, a load-displacement line, a stiffness and a static error.

:func:`analyse_recording` is the library entry point of the sensor path:

1. volts to mm along the sensor axis (scale, sign), saturation / out-of-range /
   dropout flags (:mod:`~stiffmap.sensors.convert`);
2. loads in N from the load channel (kgf, N, or V of a load cell) or from a
   table of steps, converted once with ``g``;
3. the static plateaus (:mod:`~stiffmap.sensors.plateaus`), or the step times
   given by hand;
4. slow drift removed through the zero-load plateaus (piecewise linear in time
   between them; constant beyond);
5. the least-squares line, the static error at the reference load and the
   hysteresis (:mod:`~stiffmap.sensors.fit`).

A recording that cannot give a trustworthy answer raises
:class:`~stiffmap.errors.InputError` naming the file and the time span;
whatever is doubtful but usable is listed in ``flags``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import FieldError, InputError
from ..loads import MAX_FORCE_N
from ..stiffness import DISPLACEMENT_FLOOR_MM
from ..units import G_REFERENCE_PAPER, newton_from_kgf
from .convert import (
    SampleSpan,
    describe_spans,
    displacement_from_volts,
    newton_from_load,
    spans_from_mask,
    time_gaps,
)
from .fit import Hysteresis, LinearFit, branches, fit_load_displacement, hysteresis
from .plateaus import detect_plateaus
from .recording import Recording

__all__ = ["SensorConfig", "Plateau", "SensorResult", "analyse_recording", "REFERENCE_LOAD_N"]

#: The milling study's reference load: 50 kgf with g = 9.81 m/s^2, N.
REFERENCE_LOAD_N = 490.5

_DETECT = ("auto", "load", "displacement", "both")

#: Plausible ranges of the settings that scale the data: (low, high, unit). Beyond, a value
#: is a typing mistake or a wrong unit, and the numbers it gives would be meaningless.
PLAUSIBLE = {
    "scale_um_per_v": (1e-6, 1e9, "um/V"),
    "range_v": (1e-3, 1e4, "V"),
    "g": (0.1, 100.0, "m/s^2"),
    "load_n_per_v": (1e-9, 1e9, "N/V"),
    "window_s": (1e-6, 1e6, "s"),
    "min_plateau_s": (1e-6, 1e6, "s"),
    "threshold_sigma": (0.1, 1e3, "sigma"),
}


def _pos(name: str, x, allow_none: bool = False):
    if x is None and allow_none:
        return None
    try:
        xf = float(x)
    except (TypeError, ValueError):
        raise FieldError(name, f"{{{name}}} must be a number, got {x!r}", value=x) from None
    if not (math.isfinite(xf) and xf > 0):
        raise FieldError(name, f"{{{name}}} must be a positive number, got {x!r}", value=x)
    return xf


@dataclass(frozen=True)
class SensorConfig:
    """How to read a displacement/load recording.

    Attributes
    ----------
    scale_um_per_v : float
        Displacement sensor scale, µm/V (the milling study's LDV: 640).
    range_v : float
        Sensor analog output limit, V (+-8 V).
    saturation_margin_v : float
        Samples within this of ``range_v`` are saturated, V.
    axis_sign : {+1, -1}
        -1 when a mirror flips the beam.
    load_unit : {"kgf", "N", "V"} or None
        Unit of the load channel; None: from the column name's suffix
        (``load_kgf``, ``force_n``), else kgf.
    load_n_per_v : float or None
        Load-cell scale when the load channel is in volts, N/V.
    steps : tuple of float or None
        Table of the applied loads in time order (``steps_unit``), when the file has
        no load channel (or to override it); the plateau count must match.
    steps_unit : {"kgf", "N"}
    g : float
        m/s^2 for kgf (default 9.81 as the milling study: 50 kgf = 490.5 N).
    reference_load_n : float
        The load of the static error, N (default 490.5).
    step_times_s : tuple of (float, float) or None
        The plateaus given by hand, (start, end) in s; overrides the detection.
    detect_on : {"auto", "load", "displacement", "both"}
        Channels the detector looks at; auto: both when there is a load channel.
    window_s, min_plateau_s, guard_s, threshold_sigma : float
        Detector settings (see :func:`~stiffmap.sensors.plateaus.detect_plateaus`).
    remove_drift : bool
        Subtract the drift through the zero-load plateaus.
    zero_load_n : float or None
        Plateaus with |load| below this are zero-load, N (default 1 % of the largest load).
    exclude_bad_samples : bool
        False (default): any saturated, out-of-range or missing sample is an error.
        True: such samples are left out and flagged; a saturated plateau is still an error.
    level : float
        Confidence level of the intervals.
    """

    scale_um_per_v: float = 640.0
    range_v: float = 8.0
    saturation_margin_v: float = 0.01
    axis_sign: int = 1
    load_unit: str | None = None
    load_n_per_v: float | None = None
    steps: tuple[float, ...] | None = None
    steps_unit: str = "kgf"
    g: float = G_REFERENCE_PAPER
    reference_load_n: float = REFERENCE_LOAD_N
    step_times_s: tuple[tuple[float, float], ...] | None = None
    detect_on: str = "auto"
    window_s: float = 0.25
    min_plateau_s: float = 0.5
    guard_s: float | None = None
    threshold_sigma: float = 5.0
    remove_drift: bool = True
    zero_load_n: float | None = None
    exclude_bad_samples: bool = False
    level: float = 0.95

    def __post_init__(self) -> None:
        for name in ("scale_um_per_v", "range_v", "g", "window_s", "min_plateau_s", "threshold_sigma"):
            object.__setattr__(self, name, _pos(name, getattr(self, name)))
        object.__setattr__(self, "load_n_per_v", _pos("load_n_per_v", self.load_n_per_v, True))
        for name, (lo, hi, unit) in PLAUSIBLE.items():
            v = getattr(self, name)
            if v is not None and not (lo <= v <= hi):
                raise FieldError(
                    name, f"{{{name}}} must be between {lo:g} and {hi:g} {unit}, got {v:g}", value=v
                )
        m = float(self.saturation_margin_v)
        if not (math.isfinite(m) and 0 <= m < self.range_v):
            if math.isfinite(m) and m >= 0:
                raise FieldError(
                    "range_v",
                    f"{{range_v}} must exceed the saturation margin of {m:g} V, got {self.range_v:g}",
                )
            raise FieldError(
                "saturation_margin_v",
                f"{{saturation_margin_v}} must be >= 0 V, got {self.saturation_margin_v!r}",
            )
        r = float(self.reference_load_n)
        if not math.isfinite(r) or r == 0:
            raise FieldError(
                "reference_load_n",
                f"{{reference_load_n}} must be a non-zero number, got {self.reference_load_n!r}",
            )
        if abs(r) > MAX_FORCE_N:
            raise FieldError(
                "reference_load_n", f"{{reference_load_n}} must be within +-{MAX_FORCE_N:g} N, got {r:g}"
            )
        object.__setattr__(self, "reference_load_n", r)
        if self.axis_sign not in (1, -1):
            raise FieldError("axis_sign", f"{{axis_sign}} must be +1 or -1, got {self.axis_sign!r}")
        if self.load_unit is not None and self.load_unit not in ("kgf", "N", "V"):
            raise FieldError("load_unit", f"{{load_unit}} must be 'kgf', 'N' or 'V', got {self.load_unit!r}")
        if self.steps_unit not in ("kgf", "N"):
            raise FieldError("steps_unit", f"{{steps_unit}} must be 'kgf' or 'N', got {self.steps_unit!r}")
        if self.detect_on not in _DETECT:
            raise FieldError("detect_on", f"{{detect_on}} must be one of {_DETECT}, got {self.detect_on!r}")
        if not (0 < self.level < 1):
            raise FieldError("level", f"{{level}} must be in (0, 1), got {self.level!r}")
        if self.steps is not None:
            st = tuple(float(s) for s in self.steps)
            if len(st) < 2 or not all(math.isfinite(s) for s in st):
                raise FieldError("steps", f"{{steps}} must hold at least 2 finite loads, got {self.steps!r}")
            f = newton_from_kgf(1.0, self.g) if self.steps_unit == "kgf" else 1.0
            big = [s for s in st if abs(s) * f > MAX_FORCE_N]
            if big:
                raise FieldError(
                    "steps",
                    f"{{steps}}: {big[0]:g} {self.steps_unit} is beyond +-{MAX_FORCE_N:g} N: "
                    "not a plausible load",
                )
            object.__setattr__(self, "steps", st)
        if self.step_times_s is not None:
            tt = tuple((float(a), float(b)) for a, b in self.step_times_s)
            for a, b in tt:
                if not (math.isfinite(a) and math.isfinite(b) and a < b):
                    raise FieldError(
                        "step_times_s",
                        f"{{step_times_s}}: each step time must be (start, end) with start < end, "
                        f"got ({a}, {b})",
                    )
            for (_, b0), (a1, _) in zip(tt, tt[1:], strict=False):
                if a1 < b0:
                    raise FieldError(
                        "step_times_s",
                        f"{{step_times_s}}: the step times must be in time order and not overlap: {tt}",
                    )
            object.__setattr__(self, "step_times_s", tt)
        if self.guard_s is not None and not (math.isfinite(self.guard_s) and self.guard_s >= 0):
            raise FieldError("guard_s", f"{{guard_s}} must be >= 0, got {self.guard_s!r}")
        if self.zero_load_n is not None:
            object.__setattr__(self, "zero_load_n", _pos("zero_load_n", self.zero_load_n))

    @property
    def steps_n(self) -> np.ndarray | None:
        """The table of steps in N, or None."""
        if self.steps is None:
            return None
        f = newton_from_kgf(1.0, self.g) if self.steps_unit == "kgf" else 1.0
        return np.asarray(self.steps, dtype=np.float64) * f


@dataclass(frozen=True)
class Plateau:
    """One static step of the load.

    Attributes
    ----------
    t_start_s, t_end_s : float
        First and last sample used, s.
    n : int
        Samples averaged.
    load_n, load_std_n : float
        Load and its standard deviation over the plateau, N (std NaN from a table).
    displacement_mm, std_mm : float
        Mean displacement along the sensor axis after drift removal, and the standard
        deviation of the samples, mm.
    raw_displacement_mm : float
        Mean before drift removal, mm.
    branch : str
        ``start``, ``loading``, ``unloading`` or ``hold``.
    excluded : int
        Missing samples left out of this plateau.
    """

    t_start_s: float
    t_end_s: float
    n: int
    load_n: float
    load_std_n: float
    displacement_mm: float
    std_mm: float
    raw_displacement_mm: float
    branch: str
    excluded: int = 0


@dataclass(frozen=True)
class SensorResult:
    """What one recording gives.

    Attributes
    ----------
    source : str
    plateaus : tuple of Plateau
    fit : LinearFit
    reference_load_n : float
    static_error_mm, static_error_std_mm : float
        Displacement at the reference load from the unloaded position (compliance x
        load), and its standard error, mm.
    hysteresis : Hysteresis or None
    drift_mm : float
        Drift removed between the first and the last zero-load plateau, mm (NaN when
        fewer than two).
    noise_mm : float
        Displacement noise per sample seen by the detector (1 sigma), mm.
    sample_rate_hz : float
    bad_spans : tuple of SampleSpan
        Flagged samples (only with ``exclude_bad_samples``; otherwise they are errors).
    flags : tuple of str
    """

    source: str
    plateaus: tuple[Plateau, ...]
    fit: LinearFit
    reference_load_n: float
    static_error_mm: float
    static_error_std_mm: float
    hysteresis: Hysteresis | None
    drift_mm: float
    noise_mm: float
    sample_rate_hz: float
    bad_spans: tuple[SampleSpan, ...]
    flags: tuple[str, ...]

    @property
    def stiffness_n_per_mm(self) -> float:
        return self.fit.stiffness_n_per_mm

    def to_dict(self) -> dict:
        """The JSON object of ``stiffmap sensor --json`` (µm for displacements)."""
        f = self.fit
        h = self.hysteresis
        return {
            "file": self.source,
            "steps": [
                {
                    "load_n": p.load_n,
                    "displacement_um": 1e3 * p.displacement_mm,
                    "std_um": 1e3 * p.std_mm,
                    "n": p.n,
                    "t_start_s": p.t_start_s,
                    "t_end_s": p.t_end_s,
                    "load_std_n": p.load_std_n,
                    "branch": p.branch,
                }
                for p in self.plateaus
            ],
            "stiffness_n_per_mm": f.stiffness_n_per_mm,
            "stiffness_std_n_per_mm": f.stiffness_std_n_per_mm,
            "stiffness_ci_n_per_mm": list(f.stiffness_ci_n_per_mm),
            "compliance_um_per_n": 1e3 * f.compliance_mm_per_n,
            "compliance_std_um_per_n": 1e3 * f.compliance_std_mm_per_n,
            "intercept_um": 1e3 * f.intercept_mm,
            "r2": f.r2,
            "confidence_level": f.level,
            "reference_load_n": self.reference_load_n,
            "static_error_um": 1e3 * self.static_error_mm,
            "static_error_std_um": 1e3 * self.static_error_std_mm,
            "hysteresis_um": None if h is None else 1e3 * h.max_mm,
            "hysteresis_at_load_n": None if h is None else h.at_load_n,
            "drift_um": 1e3 * self.drift_mm,
            "noise_um": 1e3 * self.noise_mm,
            "flags": list(self.flags),
        }


def _fmt_spans(spans: np.ndarray, t: np.ndarray) -> str:
    return ", ".join(f"{t[a]:.2f}-{t[b - 1]:.2f} s" for a, b in spans)


def _longest_gap(spans: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """The longest time span without a plateau (edges of the recording included), s."""
    ends = [float(t[0])] + [float(t[b - 1]) for _, b in spans]
    starts = [float(t[a]) for a, _ in spans] + [float(t[-1])]
    _, e, s = max((s - e, e, s) for e, s in zip(ends, starts, strict=True))
    return e, s


def _manual_spans(times, t: np.ndarray, src: str) -> np.ndarray:
    out = []
    for i, (a, b) in enumerate(times):
        if b < t[0] or a > t[-1]:
            raise InputError(
                f"step time {i + 1} ({a:g}-{b:g} s) is outside the recording ({t[0]:g}-{t[-1]:g} s)",
                source=src,
            )
        i0 = int(np.searchsorted(t, a, side="left"))
        i1 = int(np.searchsorted(t, b, side="right"))
        if i1 - i0 < 2:
            raise InputError(f"step time {i + 1} ({a:g}-{b:g} s) holds fewer than 2 samples", source=src)
        out.append((i0, i1))
    return np.asarray(out, dtype=int).reshape(-1, 2)


def _displacement_channel(recording: Recording) -> str:
    """``the displacement (channel 'NAME')`` when the reader said which channel it was."""
    name = recording.meta.get("displacement_channel")
    return f"the displacement (channel {name!r})" if name else "the displacement"


def _refuse_raw_codes(volts: np.ndarray, range_v: float, src: str, what: str = "the displacement") -> None:
    """Whole numbers far beyond the sensor range on most samples are DAQ codes, not volts.

    A DAQ that logs its ADC codes (int16: -32768 to 32767) without their scale writes
    integers where volts belong; read as volts, every sample would be out of range. The
    message says what the numbers probably are, instead of listing hundreds of spans.
    """
    v = volts[np.isfinite(volts)]
    if v.size < 2:
        return
    beyond = np.abs(v) > range_v
    if beyond.mean() <= 0.5 or not np.all(v == np.round(v)):
        return
    raise InputError(
        f"{what} holds whole numbers from {v.min():.0f} to {v.max():.0f}, beyond the "
        f"sensor range of +-{range_v:g} V on {beyond.mean():.0%} of the samples: raw DAQ codes (int16?) "
        "without their scale to volts? Export the scaled data (volts) from the DAQ software, or give "
        "the channel its scale (NI_Scale properties in TDMS)",
        source=src,
    )


def _refuse_constant_displacement(
    volts: np.ndarray, x: np.ndarray, ok: np.ndarray, src: str, what: str = "the displacement"
) -> None:
    """A displacement that does not change over the whole recording measured nothing.

    The usual cause in a lab: the laser spot is off the target (or on a part that does not
    move), or the sensor is stuck or not connected; the message says so.
    """
    if ok.sum() < 2:
        return
    xs = x[ok]
    span = float(xs.max() - xs.min())
    if span >= DISPLACEMENT_FLOOR_MM:
        return
    v = volts[ok]
    how = f"{v[0]:.6g} V on every sample" if span == 0 else f"it varies by {span:.3g} mm"
    raise InputError(
        f"{what} is constant over the whole recording ({how}): is the sensor on the "
        "target? (a laser spot off the target, or a stuck or disconnected sensor, reads a constant)",
        source=src,
    )


def analyse_recording(recording: Recording, config: SensorConfig | None = None) -> SensorResult:
    """Plateaus, load-displacement fit, stiffness and static error of one recording.

    Parameters
    ----------
    recording : Recording
        Time (s), displacement sensor output (V), optional load channel.
    config : SensorConfig, optional

    Returns
    -------
    SensorResult

    Raises
    ------
    InputError
        Naming the recording's source and the time span: saturated, out-of-range or
        missing samples (unless ``exclude_bad_samples``; a saturated plateau always),
        a plateau count that differs from the table of steps, no load, fewer than
        two plateaus at different loads.

    Examples
    --------
    A noise-free staircase of 0, 100, 200, 0 N on a 1 N/um structure (640 um/V sensor):

    >>> import numpy as np
    >>> t = np.arange(0, 8, 0.01)
    >>> load = np.select([t < 2, t < 4, t < 6], [0.0, 100.0, 200.0], 0.0)
    >>> rec = Recording("staircase.csv", t, load / 1000 / 0.640, load, "N", "load_n")
    >>> r = analyse_recording(rec)
    >>> len(r.plateaus), round(r.stiffness_n_per_mm)
    (4, 1000)
    """
    cfg = config or SensorConfig()
    src = recording.source or "recording"
    t = recording.time_s
    conv = _displacement(recording, cfg, src)
    load_n = _load_channel_n(recording, cfg, src)
    bad, spans, gaps = _bad_samples(conv, load_n, t)
    if spans and not cfg.exclude_bad_samples:
        _refuse_bad_samples(spans, cfg, src)
    valid = ~bad
    x = conv.displacement_mm
    if cfg.step_times_s is not None:
        pspans, use, noise_mm = _manual_plateaus(cfg.step_times_s, t, x, valid, src)
    else:
        pspans, use, noise_mm = _detected_plateaus(cfg, x, load_n, valid, recording.sample_rate_hz, src)
    _check_plateau_count(pspans, cfg, t, src)
    excluded, flags = _check_plateau_samples(
        pspans, conv.saturated | conv.out_of_range, valid, use, spans, gaps, t, src
    )
    stats, more_flags = _plateau_statistics(pspans, use, t, x, load_n, cfg)
    flags += more_flags
    try:
        fit = fit_load_displacement(stats.load_n, stats.displacement_mm, level=cfg.level)
    except ValueError as e:
        raise InputError(f"{e} (plateaus at {_fmt_spans(pspans, t)})", source=src) from None
    fmax = float(np.abs(stats.load_n).max())
    tol_n = max(0.01 * fmax, 1e-9)
    labels = branches(stats.load_n, tol_n=tol_n)
    e, se = fit.static_error_mm(cfg.reference_load_n)
    return SensorResult(
        source=src,
        plateaus=_plateaus(pspans, t, stats, labels, excluded),
        fit=fit,
        reference_load_n=cfg.reference_load_n,
        static_error_mm=float(e),
        static_error_std_mm=float(se),
        hysteresis=hysteresis(stats.load_n, stats.displacement_mm, labels, tol_n=tol_n),
        drift_mm=stats.drift_mm,
        noise_mm=noise_mm,
        sample_rate_hz=recording.sample_rate_hz,
        bad_spans=tuple(spans),
        flags=tuple(flags + _fit_flags(fit, cfg.reference_load_n, fmax)),
    )


def _displacement(recording: Recording, cfg: SensorConfig, src: str):
    """The displacement channel in mm with its bad-sample flags; raw codes and a constant refused."""
    what = _displacement_channel(recording)
    _refuse_raw_codes(recording.displacement_v, cfg.range_v, src, what)
    conv = displacement_from_volts(
        recording.displacement_v,
        recording.time_s,
        scale_um_per_v=cfg.scale_um_per_v,
        range_v=cfg.range_v,
        axis_sign=cfg.axis_sign,
        saturation_margin_v=cfg.saturation_margin_v,
    )
    _refuse_constant_displacement(recording.displacement_v, conv.displacement_mm, ~conv.bad, src, what)
    return conv


def _load_channel_n(recording: Recording, cfg: SensorConfig, src: str) -> np.ndarray | None:
    """The load channel in N (NaN where missing), or None without one (then a table of steps is needed).

    Its unit comes from ``load_unit`` or the column name (kgf by default); a unit that
    contradicts the column name, volts without a load-cell scale and loads beyond
    :data:`~stiffmap.loads.MAX_FORCE_N` are refused.
    """
    if recording.load is None:
        if cfg.steps is None:
            raise FieldError(
                "steps",
                f"no load: the file has no load channel ({recording.load_name or 'load_kgf'}) and no table "
                "of steps was given ({steps}, e.g. 0,50,40,30,20,10,0 kgf)",
                source=src,
            )
        return None
    unit = cfg.load_unit or recording.load_unit or "kgf"
    hint = recording.load_unit
    if cfg.load_unit is not None and hint is not None and hint != cfg.load_unit:
        raise FieldError(
            "load_unit",
            f"load column {recording.load_name!r} says {hint} by its name but the load unit given is "
            f"{cfg.load_unit}; rename the column or fix {{load_unit}}",
            source=src,
        )
    if unit == "V" and cfg.load_n_per_v is None:
        raise FieldError(
            "load_n_per_v",
            f"load column {recording.load_name!r} is in volts; give the load-cell scale ({{load_n_per_v}})",
            source=src,
        )
    with np.errstate(over="ignore"):
        load_n = newton_from_load(recording.load, unit, g=cfg.g, n_per_v=cfg.load_n_per_v)
    huge = np.isfinite(recording.load) & ~(np.abs(load_n) <= MAX_FORCE_N)
    if huge.any():
        i = int(np.flatnonzero(huge)[0])
        raise InputError(
            f"load channel {recording.load_name or 'load'!r}: {recording.load[i]:.6g} {unit} at "
            f"{recording.time_s[i]:.3f} s is beyond +-{MAX_FORCE_N:g} N: not a plausible load (wrong unit or "
            "load-cell scale?)",
            source=src,
        )
    return load_n


def _bad_samples(conv, load_n: np.ndarray | None, t: np.ndarray):
    """Samples not to use and the spans that name them, in time order, and the time gaps.

    Returns
    -------
    bad : ndarray of bool, shape (n,)
        Saturated, out-of-range or missing displacement, or missing load.
    spans : list of SampleSpan
        Every flagged span, time gaps included, sorted by start time.
    gaps : list of SampleSpan
        The jumps in the time stamps.
    """
    bad = conv.bad.copy()
    spans = list(conv.spans)
    if load_n is not None:
        lmiss = ~np.isfinite(load_n)
        if lmiss.any():
            bad |= lmiss
            for a, b in spans_from_mask(lmiss):
                spans.append(SampleSpan("dropout", int(a), int(b), float(t[a]), float(t[b - 1])))
    gaps = time_gaps(t)
    spans += gaps
    spans.sort(key=lambda s: s.t_start_s)
    return bad, spans, gaps


def _refuse_bad_samples(spans: list[SampleSpan], cfg: SensorConfig, src: str) -> None:
    """Bad samples are an error unless ``exclude_bad_samples``: name them, and the range when saturated."""
    kinds = sorted({s.kind for s in spans})
    hint = ""
    if "saturated" in kinds or "out of range" in kinds:
        lim = cfg.range_v * cfg.scale_um_per_v * 1e-3
        hint = (
            f"; the displacement reached the sensor range (+-{cfg.range_v:g} V x "
            f"{cfg.scale_um_per_v:g} um/V = +-{lim:.4g} mm): re-centre the sensor or use a larger range"
        )
    raise FieldError(
        "exclude_bad_samples",
        f"{' and '.join(kinds)} samples: {describe_spans(spans)}{hint}. These samples cannot be used "
        "({exclude_bad_samples} leaves missing samples out of the plateaus)",
        source=src,
    )


def _manual_plateaus(times, t: np.ndarray, x: np.ndarray, valid: np.ndarray, src: str):
    """The plateaus given by hand: ``(spans, use, noise_mm)``, the noise from the first differences."""
    pspans = _manual_spans(times, t, src)
    use = np.zeros(t.size, dtype=bool)
    for a, b in pspans:
        use[a:b] = valid[a:b]
    noise_mm = float("nan")
    d = np.diff(x[valid])
    if d.size:
        noise_mm = float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2))
    return pspans, use, noise_mm


def _detected_plateaus(cfg: SensorConfig, x, load_n, valid: np.ndarray, fs: float, src: str):
    """The plateaus found on the channels ``detect_on`` names: ``(spans, use, noise_mm)``."""
    mode = cfg.detect_on
    if mode == "auto":
        mode = "both" if load_n is not None else "displacement"
    if mode in ("load", "both") and load_n is None:
        raise InputError(f"detect_on={cfg.detect_on!r} needs a load channel; the file has none", source=src)
    sig = {"load": [load_n], "displacement": [x], "both": [x, load_n]}[mode]
    det = detect_plateaus(
        sig,
        fs,
        valid=valid,
        window_s=cfg.window_s,
        min_plateau_s=cfg.min_plateau_s,
        guard_s=cfg.guard_s,
        threshold_sigma=cfg.threshold_sigma,
    )
    noise_mm = det.noise[0] if mode != "load" and det.noise else float("nan")
    return det.spans, det.use, noise_mm


def _check_plateau_count(pspans: np.ndarray, cfg: SensorConfig, t: np.ndarray, src: str) -> None:
    """As many plateaus as the table of steps has (if any), and at least two."""
    k = pspans.shape[0]
    table = cfg.steps
    if table is not None and k != len(table):
        tab = ", ".join(f"{s:g}" for s in table)
        msg = f"found {k} plateau(s) but the table of steps has {len(table)} ({tab} {cfg.steps_unit})"
        if k:
            msg += f"; plateaus at {_fmt_spans(pspans, t)}"
        if k < len(table):
            g0, g1 = _longest_gap(pspans, t) if k else (float(t[0]), float(t[-1]))
            msg += f"; the longest span without a plateau is {g0:.2f}-{g1:.2f} s"
        msg += ". Give the plateaus by hand ({step_times_s}) or adjust {min_plateau_s} / {window_s}"
        raise FieldError(("step_times_s", "min_plateau_s", "window_s"), msg, source=src)
    if k < 2:
        raise InputError(
            f"found {k} plateau(s) ({_fmt_spans(pspans, t) or 'none'}); "
            "at least 2 at different loads are needed",
            source=src,
        )


def _check_plateau_samples(pspans, sat_mask, valid, use, spans, gaps, t, src) -> tuple[list[int], list[str]]:
    """Bad samples inside the plateaus (exclude mode): saturation is an error, dropouts are left out.

    Returns
    -------
    excluded : list of int
        Missing samples left out of each plateau.
    flags : list of str
        Plateaus with samples left out or time gaps; flagged spans outside every plateau.
    """
    excluded, flags = [], []
    for i, (a, b) in enumerate(pspans):
        if sat_mask[a:b].any():
            inside = [s for s in spans if s.kind != "dropout" and s.start < b and s.stop > a]
            raise InputError(
                f"plateau {i + 1} ({t[a]:.2f}-{t[b - 1]:.2f} s) holds {describe_spans(inside)}: "
                "its mean would be wrong; re-centre the sensor or choose a larger range",
                source=src,
            )
        nex = int((~valid[a:b]).sum())
        gap_in = [g for g in gaps if a <= g.start and g.stop <= b]
        excluded.append(nex)
        if nex or gap_in:
            flags.append(
                f"plateau {i + 1} ({t[a]:.2f}-{t[b - 1]:.2f} s): {nex} missing sample(s) left out"
                + (f", {len(gap_in)} time gap(s)" if gap_in else "")
            )
        if use[a:b].sum() < 2:
            raise InputError(
                f"plateau {i + 1} ({t[a]:.2f}-{t[b - 1]:.2f} s) has fewer than 2 usable samples", source=src
            )
    outside = [s for s in spans if not any(a <= s.start and s.stop <= b for a, b in pspans)]
    if outside:
        flags.append(f"not used (outside the plateaus): {describe_spans(outside)}")
    return excluded, flags


@dataclass(frozen=True)
class _PlateauStats:
    """Per-plateau means, shape (k,) each: load (N), displacement before/after drift removal (mm)."""

    counts: np.ndarray
    load_n: np.ndarray
    load_std_n: np.ndarray
    raw_displacement_mm: np.ndarray
    displacement_mm: np.ndarray
    std_mm: np.ndarray
    drift_mm: float


def _plateau_statistics(pspans, use, t, x, load_n, cfg: SensorConfig) -> tuple[_PlateauStats, list[str]]:
    """Each plateau's load and displacement, the drift through the zero-load plateaus removed."""
    masks = [np.zeros(t.size, dtype=bool) for _ in range(pspans.shape[0])]
    for i, (a, b) in enumerate(pspans):
        masks[i][a:b] = use[a:b]
    t_mid = np.array([t[m].mean() for m in masks])
    x_raw = np.array([x[m].mean() for m in masks])
    F, F_std, flags = _plateau_loads(masks, cfg.steps_n, load_n, t_mid)
    drift, drift_mm, drift_flags = _drift(cfg, t, t_mid, x_raw, F)
    xc = x - drift
    stats = _PlateauStats(
        counts=np.array([int(m.sum()) for m in masks]),
        load_n=F,
        load_std_n=F_std,
        raw_displacement_mm=x_raw,
        displacement_mm=np.array([xc[m].mean() for m in masks]),
        std_mm=np.array([xc[m].std(ddof=1) for m in masks]),
        drift_mm=drift_mm,
    )
    return stats, flags + drift_flags


def _plateau_loads(masks, table, load_n, t_mid) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Each plateau's load and its std, N: the table's (checked against the channel) or the channel's."""
    flags = []
    if table is None:
        F = np.array([load_n[m].mean() for m in masks])
        F_std = np.array([load_n[m].std(ddof=1) for m in masks])
        return F, F_std, flags
    F = table.copy()
    F_std = np.full(len(masks), np.nan)
    if load_n is not None:
        Fc = np.array([load_n[m].mean() for m in masks])
        tol = max(0.02 * float(np.abs(F).max()), 1e-9)
        for i in np.flatnonzero(np.abs(Fc - F) > tol):
            flags.append(
                f"plateau {i + 1} ({t_mid[i]:.2f} s): the load channel reads {Fc[i]:.4g} N, the table "
                f"says {F[i]:.4g} N"
            )
    return F, F_std, flags


def _drift(cfg: SensorConfig, t, t_mid, x_raw, F) -> tuple[np.ndarray, float, list[str]]:
    """The drift (mm, per sample) through the zero-load plateaus, its total, and flags when not removed.

    Piecewise linear in time between the zero-load plateaus, constant beyond; one zero-load
    plateau gives a constant offset; none, no drift removed.
    """
    fmax = float(np.abs(F).max())
    zero_tol = cfg.zero_load_n if cfg.zero_load_n is not None else max(0.01 * fmax, 1e-9)
    zeros = np.flatnonzero(np.abs(F) <= zero_tol)
    drift = np.zeros(t.size)
    if not cfg.remove_drift:
        return drift, float("nan"), []
    if zeros.size >= 2:
        drift = np.interp(t, t_mid[zeros], x_raw[zeros])
        return drift, float(x_raw[zeros[-1]] - x_raw[zeros[0]]), []
    if zeros.size == 1:
        return (
            np.full(t.size, x_raw[zeros[0]]),
            float("nan"),
            [
                "drift not removed: only one zero-load plateau "
                "(record one before loading and one after unloading)"
            ],
        )
    return drift, float("nan"), ["drift not removed: no zero-load plateau"]


def _fit_flags(fit: LinearFit, reference_load_n: float, fmax: float) -> list[str]:
    """What is doubtful in the fit: no standard error, negative stiffness, poor R^2, extrapolation."""
    flags = []
    if fit.dof == 0:
        flags.append("only 2 plateaus: no standard error or confidence interval")
    if fit.compliance_mm_per_n < 0:
        flags.append(
            "the displacement decreases as the load grows (negative stiffness): check the sensor axis sign "
            "(-1 behind a mirror) and the load direction"
        )
    if math.isfinite(fit.r2) and fit.r2 < 0.99:
        flags.append(f"R^2 = {fit.r2:.4f}: the plateaus are not on a line (hysteresis, slip, a bad plateau?)")
    if abs(reference_load_n) > 1.05 * fmax:
        flags.append(
            f"static error extrapolated: reference load {reference_load_n:g} N beyond the largest "
            f"plateau load {fmax:.4g} N"
        )
    return flags


def _plateaus(pspans, t, stats: _PlateauStats, labels, excluded) -> tuple[Plateau, ...]:
    return tuple(
        Plateau(
            t_start_s=float(t[a]),
            t_end_s=float(t[b - 1]),
            n=int(stats.counts[i]),
            load_n=float(stats.load_n[i]),
            load_std_n=float(stats.load_std_n[i]),
            displacement_mm=float(stats.displacement_mm[i]),
            std_mm=float(stats.std_mm[i]),
            raw_displacement_mm=float(stats.raw_displacement_mm[i]),
            branch=labels[i],
            excluded=excluded[i],
        )
        for i, (a, b) in enumerate(pspans)
    )
