"""Static plateaus of a stepped-load recording, robust to noise and slow drift.

A stepped load (e.g. 0, 50, 40, ..., 0 kgf) holds each value for a while, with
transitions in between. The detector marks each sample *stable* when the mean of
the ``w`` samples after it equals the mean of the ``w`` samples before it:

    D_i = mean(y[i : i+w]) - mean(y[i-w : i])

On a plateau D_i is noise (plus ``w`` times the slow drift rate); across a
transition it is a good part of the step. ``D`` is centred by its median (the
drift, when it is slow and the plateaus hold most of the time) and compared with
``threshold_sigma`` times its own robust spread (1.4826 MAD, which measures the
noise as it really is, white or not), with floors for quantised signals and for
steps below ``min_step_fraction`` of the signal's span. Several channels (load
and displacement) are combined: a sample is stable when it is stable in each.

Runs of stable samples separated by a short unstable blip (a spike, a bump of the
fixture) and at the same level are merged; runs shorter than ``min_plateau_s``
are dropped; a guard band is trimmed at each side next to a transition (the
structure settles after a load change). Samples marked unstable or invalid
inside a plateau are left out of its statistics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .convert import spans_from_mask

__all__ = ["PlateauDetection", "detect_plateaus", "step_statistic"]

_MAD = 1.482602218505602  # 1 / Phi^-1(3/4): MAD of Gaussian noise -> sigma


@dataclass(frozen=True)
class PlateauDetection:
    """Plateaus found in one recording.

    Attributes
    ----------
    spans : ndarray of int, shape (k, 2)
        ``[start, stop)`` sample indices of each plateau, guard bands removed.
    use : ndarray of bool, shape (n,)
        Samples to average: inside a plateau, stable and valid.
    stable : ndarray of bool, shape (n,)
        The stability mask before runs were merged and filtered.
    noise : tuple of float
        Per-sample noise of each channel as the detector saw it (1 sigma, the
        channel's unit).
    window : int
        ``w``, samples.
    thresholds : tuple of float
        The threshold on ``|D - median(D)|`` of each channel for full windows.
    """

    spans: np.ndarray
    use: np.ndarray
    stable: np.ndarray
    noise: tuple[float, ...]
    window: int
    thresholds: tuple[float, ...]

    @property
    def count(self) -> int:
        return int(self.spans.shape[0])


def _filled(y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    if valid.all():
        return y
    idx = np.arange(y.size)
    return np.interp(idx, idx[valid], y[valid])


def step_statistic(y, w: int) -> tuple[np.ndarray, np.ndarray]:
    """``D_i = mean(y[i:i+w]) - mean(y[i-w:i])`` with windows cut at the ends.

    Parameters
    ----------
    y : array_like, shape (n,)
        Finite samples.
    w : int
        Window, samples (>= 1).

    Returns
    -------
    D : ndarray, shape (n,)
        In the unit of ``y``; ``D[0]`` repeats ``D[1]``.
    scale : ndarray, shape (n,)
        ``sqrt(1/n_left + 1/n_right)``: the noise of ``D_i`` over the per-sample noise.
    """
    y = np.asarray(y, dtype=np.float64)
    n = y.size
    i = np.arange(n)
    c = np.concatenate([[0.0], np.cumsum(y)])
    lo = np.maximum(0, i - w)
    hi = np.minimum(n, i + w)
    nl = i - lo
    nr = hi - i
    nl_safe = np.maximum(nl, 1)
    ml = (c[i] - c[lo]) / nl_safe
    mr = (c[hi] - c[i]) / nr
    D = mr - ml
    scale = np.sqrt(1.0 / nl_safe + 1.0 / nr)
    if n > 1:
        D[0] = D[1]
        scale[0] = scale[1]
    return D, scale


def _quantum(y: np.ndarray) -> float:
    """The DAQ step of a quantised signal (smallest non-zero |diff|), or 0 if not quantised."""
    d = np.abs(np.diff(y))
    if d.size == 0:
        return 0.0
    nz = d[d > 0]
    if nz.size == 0 or (d == 0).mean() < 0.05:
        return 0.0
    return float(nz.min())


def _noise_and_centre(
    y: np.ndarray, D: np.ndarray, scale: np.ndarray, w: int, k: float
) -> tuple[float, float]:
    """Per-sample noise (1 sigma) as the detector sees it, and the drift part of ``D``.

    Starts from the white-noise estimate of the first differences (robust to the
    transitions, whose slope per sample is small against the noise), then
    re-measures the spread of ``D`` itself over the samples within ``k`` sigma of
    its centre, a few times: this follows noise that is not white (vibration,
    wander) up or down while the transitions, far outside, stay out. The centre
    (``w`` times the drift rate) is the median of ``D`` over the same samples.
    """
    d = np.diff(y)
    sigma = _MAD * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)
    centre = 0.0
    for _ in range(8):
        if sigma <= 0:
            break
        sel = np.abs(D - centre) <= k * sigma * scale
        if sel.sum() < max(10, w):
            break
        centre = float(np.median(D[sel]))
        z = (D[sel] - centre) / scale[sel]
        new = _MAD * float(np.median(np.abs(z)))
        if abs(new - sigma) <= 1e-3 * sigma:
            sigma = new
            break
        sigma = new
    return sigma, centre


def detect_plateaus(
    signals: Sequence,
    sample_rate_hz: float,
    *,
    valid=None,
    window_s: float = 0.25,
    min_plateau_s: float = 0.5,
    guard_s: float | None = None,
    threshold_sigma: float = 5.0,
    min_step_fraction: float = 0.002,
    split_fraction: float = 0.02,
) -> PlateauDetection:
    """Find the static plateaus of a stepped-load recording.

    Parameters
    ----------
    signals : sequence of array_like, each shape (n,)
        Channels that step together (displacement, mm; load, N). NaN allowed where
        ``valid`` is False.
    sample_rate_hz : float
    valid : array_like of bool, shape (n,), optional
        Samples that may be used (default: the finite ones in every channel).
    window_s : float
        The window ``w`` of the step statistic, s.
    min_plateau_s : float
        Shortest plateau kept, s (before the guard bands are trimmed).
    guard_s : float, optional
        Trimmed at each side of a plateau that borders a transition, s
        (default ``window_s / 2``).
    threshold_sigma : float
        Threshold on ``|D - median(D)|`` in units of its robust standard deviation.
    min_step_fraction : float
        Steps smaller than this fraction of the signal's span are not told apart
        from noise (a floor for noise-free or quantised signals).
    split_fraction : float
        Inside a stable run, a step seen with a longer window splits the run only
        when it exceeds this fraction of the span (slow drift must not split).

    Returns
    -------
    PlateauDetection

    Examples
    --------
    Three steps of 2 s at 100 Hz (0-2, 2-4, 4-6 s): three plateaus, each inside its
    step, a guard band of about ``window_s / 2`` trimmed next to each transition.

    >>> import numpy as np
    >>> y = np.repeat([0.0, 1.0, 0.5], 200)
    >>> det = detect_plateaus([y], 100.0)
    >>> [(a / 100, b / 100) for a, b in det.spans.tolist()]  # [start, stop) in s
    [(0.0, 1.89), (2.17, 3.89), (4.17, 6.0)]
    """
    fs = float(sample_rate_hz)
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"sample_rate_hz must be positive, got {sample_rate_hz!r}")
    ys, ok = _signals_and_valid(signals, valid)
    w, min_len, guard = _samples_of(fs, window_s, min_plateau_s, guard_s, threshold_sigma)
    n = ok.size
    if ok.sum() < 2 * w:
        empty = np.zeros((0, 2), dtype=int)
        return PlateauDetection(empty, np.zeros(n, bool), np.zeros(n, bool), (), w, ())
    ch, stable = _channels(ys, ok, w, threshold_sigma, min_step_fraction, split_fraction)
    _split_slow_transitions(ch, stable)
    runs = _quiet_runs(stable, w)
    merged = _merge_runs(ch, stable, runs)
    _widen_edges(ch, stable, merged)
    spans = _trimmed(merged, min_len, guard, n)
    use = np.zeros(n, dtype=bool)
    for a, b in spans:
        use[a:b] = stable[a:b] & ok[a:b]
    return PlateauDetection(spans, use, stable, tuple(ch.noise), w, tuple(ch.thresholds))


def _signals_and_valid(signals: Sequence, valid) -> tuple[list[np.ndarray], np.ndarray]:
    """The channels as float arrays of one length, and the samples valid and finite in all."""
    ys = [np.asarray(s, dtype=np.float64).ravel() for s in signals]
    if not ys:
        raise ValueError("at least one signal is needed")
    n = ys[0].size
    if any(y.size != n for y in ys):
        raise ValueError(f"signals must have the same length, got {[y.size for y in ys]}")
    ok = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool).ravel().copy()
    if ok.size != n:
        raise ValueError(f"valid must have shape ({n},), got {ok.shape}")
    for y in ys:
        ok &= np.isfinite(y)
    return ys, ok


def _samples_of(fs: float, window_s, min_plateau_s, guard_s, threshold_sigma) -> tuple[int, int, int]:
    """The window, the shortest plateau and the guard band in samples (the settings checked)."""
    for name, x in (
        ("window_s", window_s),
        ("min_plateau_s", min_plateau_s),
        ("threshold_sigma", threshold_sigma),
    ):
        if not (math.isfinite(x) and x > 0):
            raise ValueError(f"{name} must be a positive number, got {x!r}")
    w = max(2, int(round(window_s * fs)))
    min_len = max(2, int(round(min_plateau_s * fs)))
    guard = int(round((window_s / 2 if guard_s is None else guard_s) * fs))
    if guard < 0:
        raise ValueError(f"guard_s must be >= 0, got {guard_s!r}")
    return w, min_len, guard


@dataclass(frozen=True)
class _Channels:
    """What the detector knows of each channel (lists over the channels, in their units).

    ``filled``: the samples, invalid ones interpolated; ``noise``: 1 sigma per sample;
    ``thresholds``: on ``|D - median(D)|`` for full windows; ``floors``: the smallest step
    told apart from noise; ``split_floors``: the smallest step that splits a stable run;
    ``drifts``: drift per sample. ``ok``: valid samples; ``w``: the window, samples;
    ``k``: ``threshold_sigma``.
    """

    filled: list[np.ndarray]
    noise: list[float]
    thresholds: list[float]
    floors: list[float]
    split_floors: list[float]
    drifts: list[float]
    ok: np.ndarray
    w: int
    k: float

    def level(self, c: int, stable: np.ndarray, a: int, b: int) -> tuple[float, int]:
        """Mean of channel ``c`` over the stable valid samples of ``[a, b)``, and their count."""
        m = stable[a:b] & self.ok[a:b]
        cnt = int(m.sum())
        return (float(self.filled[c][a:b][m].mean()) if cnt else float("nan")), cnt

    def gap_stays(self, c: int, a: int, b: int, ref: float, tol: float) -> bool:
        """Do the running medians of y[a:b] stay within tol of ref (no excursion in the gap)?

        Medians over w samples: a spike shorter than w/2 does not move them, an excursion
        that holds longer does.
        """
        g = self.filled[c][a:b]
        if g.size == 0:
            return True
        wg = min(self.w, g.size)
        med = np.median(np.lib.stride_tricks.sliding_window_view(g, wg), axis=1)
        return bool(np.abs(med - ref).max() <= tol + 1.25 * self.k * self.noise[c] / math.sqrt(wg))


def _channels(ys, ok, w: int, k: float, min_step_fraction: float, split_fraction: float):
    """Each channel's noise, drift and thresholds, and the samples stable in every channel."""
    unstable = np.zeros(ok.size, dtype=bool)
    filled, noise, thr_full, floors, drifts, split_floors = [], [], [], [], [], []
    for y in ys:
        yf = _filled(y, ok)
        D, scale = step_statistic(yf, w)
        sigma, med = _noise_and_centre(yf, D, scale, w, k)
        q = _quantum(yf[ok])
        sigma = max(sigma, q / math.sqrt(12.0))
        lo, hi = np.percentile(yf[ok], [0.5, 99.5])
        floor = min_step_fraction * float(hi - lo)
        thr = np.maximum(k * sigma * scale, floor)
        unstable |= np.abs(D - med) > thr
        filled.append(yf)
        noise.append(sigma)
        thr_full.append(float(max(k * sigma * math.sqrt(2.0 / w), floor)))
        floors.append(floor)
        split_floors.append(max(floor, split_fraction * float(hi - lo)))
        drifts.append(med / w)  # drift per sample
    ch = _Channels(filled, noise, thr_full, floors, split_floors, drifts, ok, w, k)
    return ch, ~unstable


def _split_slow_transitions(ch: _Channels, stable: np.ndarray) -> None:
    """Split the stable runs (in ``stable``) where a longer window sees a slow transition.

    Slow transitions hide from the short window: look inside each stable run with
    longer windows (cut at the run's ends, so nothing outside it counts) and split
    it where a step shows that is also a sizeable part of the signal's span.
    """
    mult = 2
    while True:
        w2 = ch.w * mult
        runs = [r for r in spans_from_mask(stable) if r[1] - r[0] >= 2 * w2]
        if not runs:
            break
        for a, b in runs:
            for c in range(len(ch.filled)):
                D2, sc2 = step_statistic(ch.filled[c][a:b], w2)
                thr2 = np.maximum(ch.k * ch.noise[c] * sc2, ch.split_floors[c])
                stable[a:b] &= np.abs(D2 - ch.drifts[c] * w2) <= thr2
        mult *= 2


def _quiet_runs(stable: np.ndarray, w: int) -> list[list[int]]:
    """The runs of stable samples; a few quiet samples amid a spike or a transition are unmarked."""
    runs = []
    for r in spans_from_mask(stable):
        if r[1] - r[0] >= max(3, w // 4):
            runs.append(list(r))
        else:
            stable[r[0] : r[1]] = False
    return runs


def _merge_runs(ch: _Channels, stable: np.ndarray, runs: list[list[int]]) -> list[list[int]]:
    """Merge neighbouring runs at the same level whose gap stays at that level.

    The gap is a spike or a false split; a real excursion between two equal plateaus
    is kept.
    """
    merged: list[list[int]] = []
    for r in runs:
        if merged and _same_level(ch, stable, merged[-1], r):
            merged[-1][1] = r[1]
        else:
            merged.append(r)
    return merged


def _same_level(ch: _Channels, stable: np.ndarray, prev: list[int], r: list[int]) -> bool:
    """Are two runs at one level in every channel (within noise, drift and floor), the gap too?"""
    a0, b0 = prev
    for c in range(len(ch.filled)):
        la, na = ch.level(c, stable, a0, b0)
        lb, nb = ch.level(c, stable, r[0], r[1])
        if na == 0 or nb == 0:
            continue
        dist = 0.5 * ((r[0] + r[1]) - (a0 + b0))
        tol = ch.k * ch.noise[c] * math.sqrt(1 / na + 1 / nb) + abs(ch.drifts[c]) * dist
        tol = max(tol, ch.floors[c])
        if abs(la - lb) > tol or not ch.gap_stays(c, b0, r[0], 0.5 * (la + lb), tol):
            return False
    return True


def _widen_edges(ch: _Channels, stable: np.ndarray, merged: list[list[int]]) -> None:
    """Move each run's edges out (by at most w) while the next samples sit at its level.

    The step statistic stops a run up to w samples before a transition; the edges move
    by ``max(5, w // 5)`` samples at a time (``merged`` and ``stable`` are updated).
    """
    w, n, nch = ch.w, ch.ok.size, len(ch.filled)
    m = max(5, w // 5)
    for j, r in enumerate(merged):
        lo_lim = merged[j - 1][1] if j > 0 else 0
        hi_lim = merged[j + 1][0] if j + 1 < len(merged) else n
        lv = [ch.level(c, stable, r[0], r[1])[0] for c in range(nch)]
        tols = [ch.k * ch.noise[c] / math.sqrt(m) for c in range(nch)]

        def fits(a: int, b: int, lv=lv, tols=tols) -> bool:
            if not ch.ok[a:b].all():
                return False
            return all(abs(ch.filled[c][a:b].mean() - lv[c]) <= tols[c] for c in range(nch))

        a = r[0]
        while a - m >= max(lo_lim, r[0] - w) and fits(a - m, a):
            a -= m
        b = r[1]
        while b + m <= min(hi_lim, r[1] + w) and fits(b, b + m):
            b += m
        stable[a : r[0]] = True
        stable[r[1] : b] = True
        r[0], r[1] = a, b


def _trimmed(merged: list[list[int]], min_len: int, guard: int, n: int) -> np.ndarray:
    """The runs long enough, a guard band trimmed at each side next to a transition: shape (k, 2)."""
    keep = []
    for a, b in merged:
        if b - a < min_len:
            continue
        a2 = a + (guard if a > 0 else 0)
        b2 = b - (guard if b < n else 0)
        if b2 - a2 < 2:
            continue
        keep.append((a2, b2))
    return np.asarray(keep, dtype=int).reshape(-1, 2)
