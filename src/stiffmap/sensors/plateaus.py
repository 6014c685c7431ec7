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
    """
    fs = float(sample_rate_hz)
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"sample_rate_hz must be positive, got {sample_rate_hz!r}")
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
    empty = np.zeros((0, 2), dtype=int)
    if ok.sum() < 2 * w:
        return PlateauDetection(empty, np.zeros(n, bool), np.zeros(n, bool), (), w, ())

    unstable = np.zeros(n, dtype=bool)
    filled, noise, thr_full, floors, drifts, split_floors = [], [], [], [], [], []
    for y in ys:
        yf = _filled(y, ok)
        D, scale = step_statistic(yf, w)
        sigma, med = _noise_and_centre(yf, D, scale, w, threshold_sigma)
        q = _quantum(yf[ok])
        sigma = max(sigma, q / math.sqrt(12.0))
        lo, hi = np.percentile(yf[ok], [0.5, 99.5])
        floor = min_step_fraction * float(hi - lo)
        thr = np.maximum(threshold_sigma * sigma * scale, floor)
        unstable |= np.abs(D - med) > thr
        filled.append(yf)
        noise.append(sigma)
        thr_full.append(float(max(threshold_sigma * sigma * math.sqrt(2.0 / w), floor)))
        floors.append(floor)
        split_floors.append(max(floor, split_fraction * float(hi - lo)))
        drifts.append(med / w)  # drift per sample
    stable = ~unstable
    # Slow transitions hide from the short window: look inside each stable run with
    # longer windows (cut at the run's ends, so nothing outside it counts) and split
    # it where a step shows that is also a sizeable part of the signal's span.
    mult = 2
    while True:
        w2 = w * mult
        runs = [r for r in spans_from_mask(stable) if r[1] - r[0] >= 2 * w2]
        if not runs:
            break
        for a, b in runs:
            for k in range(len(ys)):
                D2, sc2 = step_statistic(filled[k][a:b], w2)
                thr2 = np.maximum(threshold_sigma * noise[k] * sc2, split_floors[k])
                stable[a:b] &= np.abs(D2 - drifts[k] * w2) <= thr2
        mult *= 2
    runs = []
    for r in spans_from_mask(stable):
        if r[1] - r[0] >= max(3, w // 4):
            runs.append(list(r))
        else:
            stable[r[0] : r[1]] = False  # a few quiet samples amid a spike or a transition

    def level(k: int, a: int, b: int) -> tuple[float, int]:
        m = stable[a:b] & ok[a:b]
        cnt = int(m.sum())
        return (float(filled[k][a:b][m].mean()) if cnt else float("nan")), cnt

    def gap_stays(k: int, a: int, b: int, ref: float, tol: float) -> bool:
        """Do the running medians of y[a:b] stay within tol of ref (no excursion in the gap)?

        Medians over w samples: a spike shorter than w/2 does not move them, an excursion
        that holds longer does.
        """
        g = filled[k][a:b]
        if g.size == 0:
            return True
        wg = min(w, g.size)
        med = np.median(np.lib.stride_tricks.sliding_window_view(g, wg), axis=1)
        return bool(np.abs(med - ref).max() <= tol + 1.25 * threshold_sigma * noise[k] / math.sqrt(wg))

    # Merge neighbouring runs at the same level whose gap stays at that level (a
    # spike, a false split); a real excursion between two equal plateaus is kept.
    merged: list[list[int]] = []
    for r in runs:
        if merged:
            a0, b0 = merged[-1]
            same = True
            for k in range(len(ys)):
                la, na = level(k, a0, b0)
                lb, nb = level(k, r[0], r[1])
                if na == 0 or nb == 0:
                    continue
                dist = 0.5 * ((r[0] + r[1]) - (a0 + b0))
                tol = threshold_sigma * noise[k] * math.sqrt(1 / na + 1 / nb) + abs(drifts[k]) * dist
                tol = max(tol, floors[k])
                if abs(la - lb) > tol or not gap_stays(k, b0, r[0], 0.5 * (la + lb), tol):
                    same = False
                    break
            if same:
                merged[-1][1] = r[1]
                continue
        merged.append(r)
    # The step statistic stops a run up to w samples before a transition; move each
    # edge out (by at most w) while the next few samples still sit at the plateau's level.
    m = max(5, w // 5)
    for j, r in enumerate(merged):
        lo_lim = merged[j - 1][1] if j > 0 else 0
        hi_lim = merged[j + 1][0] if j + 1 < len(merged) else n
        lv = [level(k, r[0], r[1])[0] for k in range(len(ys))]
        tols = [threshold_sigma * noise[k] / math.sqrt(m) for k in range(len(ys))]

        def fits(a: int, b: int, lv=lv, tols=tols) -> bool:
            if not ok[a:b].all():
                return False
            return all(abs(filled[k][a:b].mean() - lv[k]) <= tols[k] for k in range(len(ys)))

        a = r[0]
        while a - m >= max(lo_lim, r[0] - w) and fits(a - m, a):
            a -= m
        b = r[1]
        while b + m <= min(hi_lim, r[1] + w) and fits(b, b + m):
            b += m
        stable[a : r[0]] = True
        stable[r[1] : b] = True
        r[0], r[1] = a, b
    keep = []
    for a, b in merged:
        if b - a < min_len:
            continue
        a2 = a + (guard if a > 0 else 0)
        b2 = b - (guard if b < n else 0)
        if b2 - a2 < 2:
            continue
        keep.append((a2, b2))
    spans = np.asarray(keep, dtype=int).reshape(-1, 2)
    use = np.zeros(n, dtype=bool)
    for a, b in spans:
        use[a:b] = stable[a:b] & ok[a:b]
    return PlateauDetection(spans, use, stable, tuple(noise), w, tuple(thr_full))
