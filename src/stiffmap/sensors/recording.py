"""A DAQ recording in memory and the map from file channels to what they measure.

A :class:`Recording` holds what a file gave, unchanged: the time of each sample
(s), the displacement sensor's output (V) and, when recorded, the load channel
(in the unit the file carries). The :class:`ChannelMap` says which column,
channel or variable holds each of them; readers are in :mod:`stiffmap.sensors.io`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import FieldError, InputError

__all__ = [
    "ChannelMap",
    "Recording",
    "parse_channel_map",
    "load_unit_from_name",
    "LOAD_UNITS",
    "SAMPLE_RATE_RANGE_HZ",
    "MAX_TIME_S",
    "check_sample_rate",
]

#: Units a load channel or a table of steps may carry ("V" needs a load-cell scale, N/V).
LOAD_UNITS = ("kgf", "N", "V")

#: Plausible sample rates, Hz: from a dial gauge read by hand every few minutes to a fast
#: digitiser. Outside, the rate (or the time step it comes from) is a broken value.
SAMPLE_RATE_RANGE_HZ = (1e-4, 1e10)
#: Largest time stamp, s: absolute clocks (Unix, LabVIEW's 1904 epoch) stay far below it.
MAX_TIME_S = 1e12


def check_sample_rate(fs, where: str) -> float:
    """A sample rate (Hz) as a float within :data:`SAMPLE_RATE_RANGE_HZ`, else a ValueError.

    ``where`` says where the rate comes from (``"variable 'fs'"``), for the message.
    """
    lo, hi = SAMPLE_RATE_RANGE_HZ
    try:
        f = float(fs)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: {fs!r} is not a number of Hz") from None
    if not (math.isfinite(f) and lo <= f <= hi):
        raise ValueError(
            f"{where}: a sample rate of {f:g} Hz is not plausible; expected a positive number of Hz "
            f"between {lo:g} and {hi:g}"
        )
    return f


def load_unit_from_name(name: str | None) -> str | None:
    """The load unit a column name says by its suffix (``load_kgf`` -> kgf, ``force_n`` -> N)."""
    if not name:
        return None
    low = name.strip().lower()
    for suffix, unit in (("_kgf", "kgf"), ("_n", "N"), ("_v", "V")):
        if low.endswith(suffix):
            return unit
    return None


@dataclass(frozen=True)
class ChannelMap:
    """Which column (CSV), channel (TDMS) or variable (MAT) holds each signal.

    Attributes
    ----------
    displacement : str
        The displacement sensor's analog output, V. Default ``displacement_v``.
    load : str or None
        The load channel (load cell / dynamometer), in kgf, N or V. Default
        ``load_kgf``. Optional in the file unless ``load_required``; with a table
        of steps it may be absent.
    time : str or None
        Time of each sample, s. Default ``time_s``. When absent from the file, the
        time comes from ``sample_rate_hz`` or, in TDMS, from the waveform
        properties (``wf_increment``).
    sample_rate_hz : float or None
        Sample rate used when the file has no time channel.
    group : str or None
        TDMS group, or MAT struct variable, holding the channels; default: search
        all groups (TDMS) or the top-level variables (MAT).
    load_required, time_required : bool
        True when the user named the column explicitly: its absence is an error.
    """

    displacement: str = "displacement_v"
    load: str | None = "load_kgf"
    time: str | None = "time_s"
    sample_rate_hz: float | None = None
    group: str | None = None
    load_required: bool = False
    time_required: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.displacement, str) or not self.displacement.strip():
            raise ValueError(f"displacement channel must be a non-empty name, got {self.displacement!r}")
        if self.sample_rate_hz is not None:
            object.__setattr__(
                self, "sample_rate_hz", check_sample_rate(self.sample_rate_hz, "sample_rate_hz")
            )


_MAP_KEYS = {
    "displacement": "displacement",
    "disp": "displacement",
    "load": "load",
    "force": "load",
    "time": "time",
    "rate": "sample_rate_hz",
    "sample_rate_hz": "sample_rate_hz",
    "fs": "sample_rate_hz",
    "group": "group",
}


def parse_channel_map(text: str | None) -> ChannelMap:
    """Parse ``displacement=COL,load=COL,time=COL[,rate=HZ][,group=NAME]``.

    Keys left out keep their defaults (``displacement_v``, ``load_kgf``,
    ``time_s``). ``load=none`` says there is no load channel; ``time=none`` that
    there is no time channel (then give ``rate=HZ``, or read TDMS waveforms).

    Raises
    ------
    FieldError
        Field ``"channel_map"``: an unknown key, a missing ``=`` or a rate that is not a
        positive number (the command line words it ``--channel-map``, campaign.toml
        ``sensor.channel_map``).
    """
    if text is None or not text.strip():
        return ChannelMap()
    kw: dict = {}
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        if "=" not in part:
            raise FieldError("channel_map", f"{part!r} should look like NAME=COLUMN (e.g. load=force_n)")
        k, v = (s.strip() for s in part.split("=", 1))
        key = _MAP_KEYS.get(k.lower())
        if key is None:
            raise FieldError(
                "channel_map", f"unknown key {k!r}; expected displacement, load, time, rate or group"
            )
        if key == "sample_rate_hz":
            try:
                kw[key] = check_sample_rate(v, f"rate={v}")
            except ValueError as e:
                raise FieldError("channel_map", str(e)) from None
            continue
        if not v:
            raise FieldError("channel_map", f"{k}= needs a column name")
        if key in ("load", "time") and v.lower() == "none":
            kw[key] = None
            continue
        kw[key] = v
        if key == "load":
            kw["load_required"] = True
        if key == "time":
            kw["time_required"] = True
    return ChannelMap(**kw)


@dataclass(frozen=True)
class Recording:
    """One DAQ recording, as read (no unit conversion, no sample removed).

    Attributes
    ----------
    source : str
        Where it came from (file name), used in every message.
    time_s : ndarray, shape (n,), s
        Time of each sample, strictly increasing (a gap in it is a dropout).
    displacement_v : ndarray, shape (n,), V
        Displacement sensor output; NaN marks a missing sample (dropout).
    load : ndarray, shape (n,), or None
        Load channel in ``load_unit``; NaN marks a missing sample.
    load_unit : str or None
        ``"kgf"``, ``"N"`` or ``"V"`` when known from the column name, else None.
    load_name : str or None
        Name of the load column in the file.
    meta : dict
        What else the file said (sample rate, TDMS properties...).
    """

    source: str
    time_s: np.ndarray
    displacement_v: np.ndarray
    load: np.ndarray | None = None
    load_unit: str | None = None
    load_name: str | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        src = self.source or "recording"
        t = np.asarray(self.time_s, dtype=np.float64).ravel()
        v = np.asarray(self.displacement_v, dtype=np.float64).ravel()
        if t.size != v.size:
            raise InputError(
                f"time has {t.size} samples but the displacement has {v.size}; expected the same count",
                source=src,
            )
        if t.size < 2:
            raise InputError(f"{t.size} sample(s); a recording needs many samples", source=src)
        if not np.all(np.isfinite(t)):
            i = int(np.flatnonzero(~np.isfinite(t))[0])
            raise InputError(f"time of sample {i} is not a finite number", source=src)
        if np.any(np.abs(t) > MAX_TIME_S):
            i = int(np.flatnonzero(np.abs(t) > MAX_TIME_S)[0])
            raise InputError(
                f"time of sample {i} is {t[i]:.6g} s, beyond +-{MAX_TIME_S:g} s: not a plausible time "
                "(are the times in s?)",
                source=src,
            )
        dt = np.diff(t)
        if np.any(dt <= 0):
            i = int(np.flatnonzero(dt <= 0)[0])
            raise InputError(
                f"time must increase: sample {i + 1} at {t[i + 1]:.6g} s follows {t[i]:.6g} s", source=src
            )
        try:
            check_sample_rate(
                1.0 / float(np.median(dt)),
                f"the time stamps give a median step of {float(np.median(dt)):.6g} s",
            )
        except ValueError as e:
            raise InputError(f"{e} (are the times in s?)", source=src) from None
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "displacement_v", v)
        if self.load is not None:
            ld = np.asarray(self.load, dtype=np.float64).ravel()
            if ld.size != t.size:
                raise InputError(
                    f"load channel has {ld.size} samples but time has {t.size}; expected the same count",
                    source=src,
                )
            object.__setattr__(self, "load", ld)
        if self.load_unit is not None and self.load_unit not in LOAD_UNITS:
            raise ValueError(f"load_unit must be one of {LOAD_UNITS}, got {self.load_unit!r}")

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)

    @property
    def sample_rate_hz(self) -> float:
        """Nominal sample rate, Hz: the inverse of the median sample interval."""
        return float(1.0 / np.median(np.diff(self.time_s)))

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])
