"""Simulated displacement-sensor recordings of stepped loads, with known truth.

What the milling study's test-bed records, made from a known compliance: a
laser Doppler vibrometer in displacement mode (analog output at
``scale_um_per_v``, 640 µm/V, limited to +-``range_v``, 8 V) sampled by a DAQ
(``daq_bits`` over +-``daq_range_v``: 16 bit over +-10 V), while a load steps
through a table (0, 50, 40, 30, 20, 10, 0 kgf) read on a dynamometer (0.05 kgf
resolution) or not recorded at all.

The signal chain, per sample:

    F(t)    the applied load: plateaus joined by raised-cosine transitions, N
    x(t)    = c * play(F)(t): compliance c (mm/N) along the sensor axis; play() is a
            backlash of half-width ``hysteresis_n`` (identity when 0), so the
            unloading branch sits c * 2 * hysteresis_n above the loading one;
            optionally lagging the load by a first-order settling (``settle_s``)
    drift   linear rate + a slow random wander (sum of sinusoids, periods of
            ``drift_period_s`` and longer), µm
    noise   white Gaussian + an optional vibration line (e.g. 50 Hz), µm
    volts   axis_sign * (x + drift + noise + offset) / scale, clipped at +-range_v
            (saturation), quantised by the DAQ and clipped at its range
    load    F in kgf or N, with reading noise, rounded to the display resolution

The truth (compliance, static error at the reference load, the applied load and
time span of every plateau) comes back beside the recording. The compliance
along the sensor axis is an argument: a number, a callable of the point (or of the
point and the direction) or a mechanism model with ``static_error(points, force)``
(the 3PRR of :mod:`stiffmap.models`), so any stiffness field can drive it.
"""

from __future__ import annotations

import inspect
import math
import numbers
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io import atomic_write_text, dumps_json
from ..sensors.io import write_recording
from ..sensors.recording import Recording
from ..units import G_REFERENCE_PAPER, newton_from_kgf

__all__ = [
    "DaqChain",
    "LoadSteps",
    "TraceTruth",
    "SimulatedTrace",
    "simulate_trace",
    "simulate_point_traces",
    "compliance_along",
    "PAPER_STEPS_KGF",
]

#: The milling study's load sequence, kgf: zero, then 50 decreasing to 0 (a zero plateau first,
#: so that the drift can be removed between the two zero-load plateaus).
PAPER_STEPS_KGF = (0.0, 50.0, 40.0, 30.0, 20.0, 10.0, 0.0)


@dataclass(frozen=True)
class DaqChain:
    """The displacement sensor and the DAQ.

    Attributes
    ----------
    scale_um_per_v : float
        Sensor scale, µm/V (640: the milling study's LDV setting).
    range_v : float
        Sensor output limit, V (saturation beyond).
    daq_range_v : float
        DAQ input range, +-V.
    daq_bits : int
        DAQ resolution; 0 for no quantisation.
    sample_rate_hz : float
    noise_um : float
        White displacement noise, 1 sigma, µm.
    vibration_um, vibration_hz : float
        Amplitude (µm) and frequency of a vibration line.
    drift_um_per_s : float
        Linear drift rate, µm/s.
    drift_wander_um : float
        RMS of the slow random drift, µm.
    drift_period_s : float
        Shortest period of the slow random drift, s.
    offset_um : float
        Sensor reading at zero load, µm.
    """

    scale_um_per_v: float = 640.0
    range_v: float = 8.0
    daq_range_v: float = 10.0
    daq_bits: int = 16
    sample_rate_hz: float = 1000.0
    noise_um: float = 1.0
    vibration_um: float = 0.0
    vibration_hz: float = 50.0
    drift_um_per_s: float = 0.05
    drift_wander_um: float = 1.0
    drift_period_s: float = 300.0
    offset_um: float = 0.0

    def __post_init__(self) -> None:
        for name in ("scale_um_per_v", "range_v", "daq_range_v", "sample_rate_hz", "drift_period_s"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {getattr(self, name)!r}")
        for name in ("noise_um", "vibration_um", "drift_wander_um"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if int(self.daq_bits) != self.daq_bits or not (0 <= self.daq_bits <= 32):
            raise ValueError(f"daq_bits must be an integer in [0, 32], got {self.daq_bits!r}")

    @property
    def lsb_v(self) -> float:
        """The DAQ's quantisation step, V (0 without quantisation)."""
        return 0.0 if self.daq_bits == 0 else 2 * self.daq_range_v / 2**self.daq_bits


@dataclass(frozen=True)
class LoadSteps:
    """The stepped load and how it is recorded.

    Attributes
    ----------
    steps : tuple of float
        Loads in time order, in ``unit``.
    unit : {"kgf", "N"}
    plateau_s, transition_s : float
        Mean plateau and transition durations, s.
    jitter : float
        Each duration is scaled by a uniform factor in [1 - jitter, 1 + jitter].
    load_channel : bool
        Record the load (dynamometer / load cell) as a channel; else only the table.
    load_noise : float
        Reading noise of the load channel, 1 sigma, ``unit``.
    load_resolution : float
        Display resolution of the load channel, ``unit`` (0.05 kgf in the study); 0: none.
    load_error : float
        Spread of the applied load around the nominal step, 1 sigma, ``unit`` (what a
        table of steps does not know).
    """

    steps: tuple[float, ...] = PAPER_STEPS_KGF
    unit: str = "kgf"
    plateau_s: float = 4.0
    transition_s: float = 1.0
    jitter: float = 0.25
    load_channel: bool = True
    load_noise: float = 0.02
    load_resolution: float = 0.05
    load_error: float = 0.0

    def __post_init__(self) -> None:
        st = tuple(float(s) for s in self.steps)
        if len(st) < 2 or not all(math.isfinite(s) for s in st):
            raise ValueError(f"steps must hold at least 2 finite loads, got {self.steps!r}")
        object.__setattr__(self, "steps", st)
        if self.unit not in ("kgf", "N"):
            raise ValueError(f"unit must be 'kgf' or 'N', got {self.unit!r}")
        for name in ("plateau_s", "transition_s"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of s, got {getattr(self, name)!r}")
        if not (0 <= self.jitter < 1):
            raise ValueError(f"jitter must be in [0, 1), got {self.jitter!r}")
        for name in ("load_noise", "load_resolution", "load_error"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class TraceTruth:
    """What the simulated recording should give.

    Attributes
    ----------
    compliance_mm_per_n : float
        Along the sensor axis (the sign of the displacement per unit load).
    reference_load_n : float
    static_error_mm : float
        compliance x reference load.
    loads_n : ndarray, shape (k,)
        Load actually applied on each plateau, N.
    plateaus_s : ndarray, shape (k, 2)
        Start and end of each constant-load span, s.
    steps, unit :
        The nominal table of steps.
    axis_sign : int
    hysteresis_n : float
    g : float
    point, direction : ndarray or None
    file : str
    """

    compliance_mm_per_n: float
    reference_load_n: float
    static_error_mm: float
    loads_n: np.ndarray
    plateaus_s: np.ndarray
    steps: tuple[float, ...]
    unit: str
    axis_sign: int
    hysteresis_n: float
    g: float
    point: np.ndarray | None = None
    direction: np.ndarray | None = None
    file: str = ""

    def to_dict(self) -> dict:
        return {
            "file": self.file,
            "point": self.point,
            "direction": self.direction,
            "compliance_mm_per_n": self.compliance_mm_per_n,
            "stiffness_n_per_mm": 1.0 / self.compliance_mm_per_n if self.compliance_mm_per_n else None,
            "reference_load_n": self.reference_load_n,
            "static_error_um": 1e3 * self.static_error_mm,
            "loads_n": self.loads_n,
            "plateaus_s": self.plateaus_s,
            "steps": list(self.steps),
            "steps_unit": self.unit,
            "axis_sign": self.axis_sign,
            "hysteresis_n": self.hysteresis_n,
            "g": self.g,
        }


@dataclass(frozen=True)
class SimulatedTrace:
    """A simulated recording and its truth."""

    recording: Recording
    truth: TraceTruth
    displacement_true_mm: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))


def _play(F: np.ndarray, r: float) -> np.ndarray:
    """Backlash (play) operator of half-width r on a force history (starts at F[0] clipped)."""
    if r <= 0:
        return F.copy()
    out = np.empty_like(F)
    p = 0.0
    for i, f in enumerate(F):
        p = max(f - r, min(f + r, p))
        out[i] = p
    return out


def _rng(seed) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def simulate_trace(
    compliance_mm_per_n: float | None = None,
    *,
    static_error_mm: float | None = None,
    chain: DaqChain | None = None,
    protocol: LoadSteps | None = None,
    g: float = G_REFERENCE_PAPER,
    reference_load_n: float = 490.5,
    axis_sign: int = 1,
    hysteresis_n: float = 0.0,
    settle_s: float = 0.0,
    dropouts: Sequence[tuple[float, float]] = (),
    dropout_kind: str = "nan",
    seed: int | np.random.Generator | None = 0,
    source: str = "simulated",
) -> SimulatedTrace:
    """One simulated recording of a stepped load.

    Parameters
    ----------
    compliance_mm_per_n : float
        Displacement along the sensor axis per N of load, mm/N. Or give
    static_error_mm : float
        the displacement at ``reference_load_n`` instead, mm.
    chain : DaqChain, optional
    protocol : LoadSteps, optional
    g : float
        m/s^2 for kgf (9.81, the milling study's).
    reference_load_n : float
    axis_sign : {+1, -1}
        -1 for a mirror in the beam: the file's volts have the opposite sign.
    hysteresis_n : float
        Half-width of the backlash between loading and unloading, N.
    settle_s : float
        Time constant of a first-order lag of the structure behind the load (creep,
        friction settling), s; 0: none.
    dropouts : sequence of (start_s, end_s)
        Spans where the sensor signal is lost.
    dropout_kind : {"nan", "gap"}
        ``nan``: the displacement samples are NaN (an empty CSV cell); ``gap``: the
        samples are missing from every channel (a jump in the time stamps).
    seed : int or Generator
        The same seed gives the same recording, bit for bit.
    source : str
        Name of the recording (the file name once written).

    Returns
    -------
    SimulatedTrace
    """
    c = _compliance_of(compliance_mm_per_n, static_error_mm, reference_load_n)
    if axis_sign not in (1, -1):
        raise ValueError(f"axis_sign must be +1 or -1, got {axis_sign!r}")
    if dropout_kind not in ("nan", "gap"):
        raise ValueError(f"dropout_kind must be 'nan' or 'gap', got {dropout_kind!r}")
    ch = chain or DaqChain()
    pr = protocol or LoadSteps()
    rng = _rng(seed)
    fs = float(ch.sample_rate_hz)
    dt = 1.0 / fs
    to_n = newton_from_kgf(1.0, g) if pr.unit == "kgf" else 1.0
    t, L, applied, edges = _load_history(pr, rng, fs, dt)
    x_mm = _structure_response(L * to_n, c, hysteresis_n, settle_s, dt)
    v = _sensor_volts(x_mm, t, ch, rng, axis_sign)
    load = _load_channel(L, pr, rng)
    rec, keep = _recording(source, t, v, load, pr.unit, dropouts, dropout_kind)
    truth = TraceTruth(
        compliance_mm_per_n=c,
        reference_load_n=float(reference_load_n),
        static_error_mm=c * float(reference_load_n),
        loads_n=applied * to_n,
        plateaus_s=edges.reshape(len(pr.steps), 2),
        steps=pr.steps,
        unit=pr.unit,
        axis_sign=axis_sign,
        hysteresis_n=float(hysteresis_n),
        g=float(g),
        file=source,
    )
    return SimulatedTrace(rec, truth, x_mm[keep])


def _load_channel(L: np.ndarray, pr: LoadSteps, rng: np.random.Generator) -> np.ndarray | None:
    """The recorded load (noise, resolution), None when the protocol records none."""
    if not pr.load_channel:
        return None
    load = L + (rng.normal(scale=pr.load_noise, size=L.size) if pr.load_noise > 0 else 0.0)
    if pr.load_resolution > 0:
        load = np.round(load / pr.load_resolution) * pr.load_resolution
    return load


def _recording(source, t, v, load, unit, dropouts, dropout_kind) -> tuple[Recording, np.ndarray]:
    """The recording with its dropouts (NaN volts, or samples left out: ``keep``), and ``keep``."""
    keep = np.ones(t.size, dtype=bool)
    for a, b in dropouts:
        m = (t >= a) & (t <= b)
        if dropout_kind == "nan":
            v[m] = np.nan
        else:
            keep &= ~m
    rec = Recording(
        source=source,
        time_s=t[keep],
        displacement_v=v[keep],
        load=None if load is None else load[keep],
        load_unit=unit if load is not None else None,
        load_name=(f"load_{unit.lower()}" if load is not None else None),
        meta={"simulated": True},
    )
    return rec, keep


def _compliance_of(compliance_mm_per_n, static_error_mm, reference_load_n) -> float:
    """The compliance (mm/N) from exactly one of the compliance and the static error."""
    if (compliance_mm_per_n is None) == (static_error_mm is None):
        raise ValueError("give exactly one of compliance_mm_per_n and static_error_mm")
    if static_error_mm is not None:
        compliance_mm_per_n = float(static_error_mm) / float(reference_load_n)
    c = float(compliance_mm_per_n)
    if not math.isfinite(c):
        raise ValueError(f"compliance must be finite, got {compliance_mm_per_n!r}")
    return c


def _load_history(pr: LoadSteps, rng: np.random.Generator, fs: float, dt: float):
    """The sample times, the load (in the steps' unit: constant on plateaus, raised cosine in
    between), the loads applied (the steps with their error) and the plateaus' edges."""
    k = len(pr.steps)
    nominal = np.asarray(pr.steps)
    applied = nominal + (rng.normal(scale=pr.load_error, size=k) if pr.load_error > 0 else 0.0)
    dur_p = pr.plateau_s * rng.uniform(1 - pr.jitter, 1 + pr.jitter, size=k)
    dur_t = pr.transition_s * rng.uniform(1 - pr.jitter, 1 + pr.jitter, size=k - 1)
    edges = np.zeros(2 * k)
    tcur = 0.0
    for i in range(k):
        edges[2 * i] = tcur
        tcur += dur_p[i]
        edges[2 * i + 1] = tcur
        if i < k - 1:
            tcur += dur_t[i]
    n = int(math.floor(tcur * fs)) + 1
    t = np.arange(n) * dt
    L = np.empty(n)
    for i in range(k):
        a, b = edges[2 * i], edges[2 * i + 1]
        L[(t >= a) & (t <= b)] = applied[i]
        if i < k - 1:
            c0 = b
            c1 = edges[2 * i + 2]
            m = (t > c0) & (t < c1)
            s = (t[m] - c0) / (c1 - c0)
            L[m] = applied[i] + (applied[i + 1] - applied[i]) * 0.5 * (1 - np.cos(np.pi * s))
    return t, L, applied, edges


def _structure_response(F: np.ndarray, c: float, hysteresis_n, settle_s, dt: float) -> np.ndarray:
    """The displacement (mm) under the force history F (N): compliance, play, first-order lag."""
    x_mm = c * _play(F, float(hysteresis_n))
    if settle_s < 0 or not math.isfinite(settle_s):
        raise ValueError(f"settle_s must be >= 0, got {settle_s!r}")
    if settle_s > 0:
        from scipy.signal import lfilter

        alpha = dt / (settle_s + dt)
        x_mm = lfilter([alpha], [1.0, alpha - 1.0], x_mm, zi=[(1.0 - alpha) * x_mm[0]])[0]
    return x_mm


def _sensor_volts(x_mm, t, ch: DaqChain, rng: np.random.Generator, axis_sign: int) -> np.ndarray:
    """The sensor's volts: the displacement with drift, noise, vibration and offset, clipped to
    the sensor's range and quantised by the DAQ."""
    n = t.size
    # Slow drift: linear + random wander (three sinusoids, periods >= drift_period_s).
    drift_um = ch.drift_um_per_s * t
    if ch.drift_wander_um > 0:
        periods = ch.drift_period_s * rng.uniform(1.0, 3.0, size=3)
        phases = rng.uniform(0, 2 * np.pi, size=3)
        amp = ch.drift_wander_um * math.sqrt(2.0 / 3.0)
        drift_um = drift_um + amp * np.sin(2 * np.pi * t[:, None] / periods + phases).sum(axis=1)
    noise_um = rng.normal(scale=ch.noise_um, size=n) if ch.noise_um > 0 else np.zeros(n)
    if ch.vibration_um > 0:
        noise_um = noise_um + ch.vibration_um * np.sin(
            2 * np.pi * ch.vibration_hz * t + rng.uniform(0, 2 * np.pi)
        )
    reading_um = 1e3 * x_mm + drift_um + noise_um + ch.offset_um
    v = axis_sign * reading_um / ch.scale_um_per_v
    v = np.clip(v, -ch.range_v, ch.range_v)
    if ch.lsb_v > 0:
        v = np.clip(np.round(v / ch.lsb_v) * ch.lsb_v, -ch.daq_range_v, ch.daq_range_v - ch.lsb_v)
    return v


def _n_params(f: Callable) -> int:
    try:
        sig = inspect.signature(f)
    except (TypeError, ValueError):
        return 1
    ps = [
        p
        for p in sig.parameters.values()
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty
    ]
    return len(ps)


def compliance_along(compliance, point, direction) -> float:
    """Compliance along a unit direction at a point, mm/N, from any of the accepted sources.

    Parameters
    ----------
    compliance : float, callable or mechanism
        A number (mm/N, the same everywhere); ``f(point)`` or ``f(point, direction)``
        returning mm/N; or an object with ``static_error(points, force)`` returning
        the displacement (mm) under a force (N), such as a model of
        :mod:`stiffmap.models`: the compliance is ``u . static_error(p, 1 N * u)``.
    point : array_like, shape (d,), mm
    direction : array_like, shape (d,), unit vector

    Returns
    -------
    float, mm/N
    """
    p = np.asarray(point, dtype=np.float64)
    u = np.asarray(direction, dtype=np.float64)
    if isinstance(compliance, numbers.Real):
        return float(compliance)
    if hasattr(compliance, "static_error"):
        e = np.asarray(compliance.static_error(p[None, :], u), dtype=np.float64).reshape(-1)
        return float(e[: u.size] @ u)
    if callable(compliance):
        return float(compliance(p, u) if _n_params(compliance) >= 2 else compliance(p))
    raise TypeError(
        f"compliance must be a number, a callable or an object with static_error(); got {type(compliance)}"
    )


_AXES = "xyz"


def simulate_point_traces(
    out_dir: str | os.PathLike,
    points,
    directions,
    compliance,
    *,
    fmt: str = "csv",
    axis_signs=None,
    chain: DaqChain | None = None,
    protocol: LoadSteps | None = None,
    g: float = G_REFERENCE_PAPER,
    reference_load_n: float = 490.5,
    seed: int = 0,
) -> list[TraceTruth]:
    """Recordings at several points and directions, written as a sensor campaign.

    Writes one recording per (point, direction) (``trace_000.csv``...), an
    ``index.csv`` (columns ``x, y[, z]`` (mm), ``ux, uy[, uz]`` (unit direction of the
    load and of the measurement), ``file``, ``axis_sign``) that
    :func:`stiffmap.sensors.batch.read_measurement_index` reads, and ``truth.json``.

    Parameters
    ----------
    out_dir : path-like
    points : array_like, shape (m, d), mm
    directions : array_like, shape (m, d)
        Direction of the load and of the sensor axis at each point (normalised here).
    compliance : float, callable or mechanism
        See :func:`compliance_along`.
    fmt : {"csv", "tdms", "mat"}
    axis_signs : array_like of {+1, -1}, shape (m,), optional
        -1 where a mirror flips the beam (default +1 everywhere).
    chain, protocol, g, reference_load_n :
        As in :func:`simulate_trace`.
    seed : int
        Recording i uses the seed sequence (seed, i): reproducible bit for bit.

    Returns
    -------
    list of TraceTruth
    """
    P, U, signs = _checked_points(points, directions, axis_signs)
    m, d = P.shape
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ext = {"csv": ".csv", "tdms": ".tdms", "mat": ".mat"}[fmt]
    truths = []
    rows = [",".join([*_AXES[:d], *(f"u{a}" for a in _AXES[:d]), "file", "axis_sign"])]
    for i in range(m):
        c = compliance_along(compliance, P[i], U[i])
        name = f"trace_{i:03d}{ext}"
        tr = simulate_trace(
            c,
            chain=chain,
            protocol=protocol,
            g=g,
            reference_load_n=reference_load_n,
            axis_sign=int(signs[i]),
            seed=np.random.default_rng([seed, i]),
            source=name,
        )
        write_recording(tr.recording, out / name, fmt)
        truth = TraceTruth(**{**tr.truth.__dict__, "point": P[i], "direction": U[i], "file": name})
        truths.append(truth)
        rows.append(
            ",".join([*(f"{v:.17g}" for v in P[i]), *(f"{v:.17g}" for v in U[i]), name, str(signs[i])])
        )
    atomic_write_text(out / "index.csv", "\n".join(rows) + "\n")
    atomic_write_text(out / "truth.json", dumps_json({"traces": [tr.to_dict() for tr in truths]}) + "\n")
    return truths


def _checked_points(points, directions, axis_signs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points, unit directions and axis signs of :func:`simulate_point_traces`, checked."""
    P = np.asarray(points, dtype=np.float64)
    U = np.asarray(directions, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (m, 2) or (m, 3), got {P.shape}")
    if U.shape != P.shape:
        raise ValueError(f"directions must have the shape of points {P.shape}, got {U.shape}")
    norms = np.linalg.norm(U, axis=1)
    if np.any(norms == 0) or not np.all(np.isfinite(U)):
        raise ValueError("every direction must be a finite non-zero vector")
    U = U / norms[:, None]
    m = P.shape[0]
    signs = np.ones(m, dtype=int) if axis_signs is None else np.asarray(axis_signs, dtype=int).ravel()
    if signs.shape != (m,) or not np.all(np.isin(signs, (1, -1))):
        raise ValueError(f"axis_signs must be {m} values of +1 or -1")
    return P, U, signs
