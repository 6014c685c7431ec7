"""Load-displacement line, its uncertainty, branches and hysteresis; the plateau detector alone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from stiffmap.sensors.convert import displacement_from_volts, spans_from_mask, time_gaps
from stiffmap.sensors.fit import branches, fit_load_displacement, hysteresis
from stiffmap.sensors.plateaus import detect_plateaus, step_statistic


def test_fit_matches_scipy_linregress(rng):
    """An independent implementation (scipy.stats.linregress) gives the same slope, intercept, errors."""
    for _ in range(20):
        F = np.sort(rng.uniform(0, 500, size=int(rng.integers(3, 12))))
        x = rng.normal(0.01, 0.005) + rng.uniform(5e-4, 5e-3) * F + rng.normal(scale=2e-3, size=F.size)
        f = fit_load_displacement(F, x)
        ref = stats.linregress(F, x)
        assert f.compliance_mm_per_n == pytest.approx(ref.slope, rel=1e-10, abs=1e-15)
        assert f.intercept_mm == pytest.approx(ref.intercept, rel=1e-9, abs=1e-12)
        assert f.compliance_std_mm_per_n == pytest.approx(ref.stderr, rel=1e-9)
        assert f.intercept_std_mm == pytest.approx(ref.intercept_stderr, rel=1e-9)
        assert f.r2 == pytest.approx(ref.rvalue**2, rel=1e-10)
        assert f.stiffness_n_per_mm == pytest.approx(1 / ref.slope, rel=1e-10)
        # delta method: s_k = s_c / c^2
        assert f.stiffness_std_n_per_mm == pytest.approx(ref.stderr / ref.slope**2, rel=1e-9)
        assert f.residuals_mm == pytest.approx(x - (ref.intercept + ref.slope * F), abs=1e-12)


def test_confidence_interval_covers_the_truth_at_its_level(rng):
    """Over 2000 seeded draws the 95 % interval of the compliance covers the true one 95 % of the time."""
    F = np.array([0.0, 490.5, 392.4, 294.3, 196.2, 98.1, 0.0])
    c_true = 2e-3
    hits = 0
    n = 2000
    for _ in range(n):
        x = c_true * F + rng.normal(scale=3e-3, size=F.size)
        lo, hi = fit_load_displacement(F, x, level=0.95).compliance_ci_mm_per_n
        hits += lo <= c_true <= hi
    # Binomial(2000, 0.95): sd 0.49 %; 4 sd either side.
    assert abs(hits / n - 0.95) <= 0.02
    f = fit_load_displacement(F, c_true * F + 1e-3 * np.array([1, -1, 0.5, 0, -0.5, 1, -1]))
    k_lo, k_hi = f.stiffness_ci_n_per_mm
    c_lo, c_hi = f.compliance_ci_mm_per_n
    assert (k_lo, k_hi) == pytest.approx((1 / c_hi, 1 / c_lo), rel=1e-12)
    assert f.static_error_mm(490.5) == pytest.approx(
        (f.compliance_mm_per_n * 490.5, f.compliance_std_mm_per_n * 490.5)
    )


def test_degenerate_fits_are_refused():
    with pytest.raises(ValueError, match="at least 2 load-displacement pairs"):
        fit_load_displacement([1.0], [2.0])
    with pytest.raises(ValueError, match=r"all loads are equal \(98\.1 N\)"):
        fit_load_displacement([98.1, 98.1, 98.1], [1, 2, 3])
    with pytest.raises(ValueError, match="finite"):
        fit_load_displacement([0, 1, np.nan], [1, 2, 3])
    two = fit_load_displacement([0, 100], [0, 0.2])
    assert two.dof == 0 and np.isnan(two.compliance_std_mm_per_n)
    assert two.compliance_mm_per_n == pytest.approx(2e-3, rel=1e-12)


def test_branches_and_hysteresis_by_hand():
    F = np.array([0, 100, 200, 300, 200, 100, 0.0])
    lab = branches(F, tol_n=1.0)
    assert lab == ["start", "loading", "loading", "loading", "unloading", "unloading", "unloading"]
    x = np.array([0, 0.10, 0.20, 0.30, 0.23, 0.13, 0.02])
    h = hysteresis(F, x, lab, tol_n=1.0)
    # unloading minus loading at 100 N: 0.03, at 200: 0.03, at 0: 0.02 -> largest 0.03 at 100 (first)
    assert h.max_mm == pytest.approx(0.03, abs=1e-12)
    assert h.at_load_n in (100.0, 200.0)
    assert h.ratio == pytest.approx(0.1, rel=1e-12)
    assert hysteresis(F[:4], x[:4], lab[:4], tol_n=1.0) is None


def test_detector_on_a_noise_free_staircase():
    """Sharp steps at known samples: plateaus between them, none across them."""
    fs = 100.0
    levels = [0.0, 1.0, 0.8, 0.6, 0.0]
    n_each = 300
    y = np.repeat(levels, n_each)
    det = detect_plateaus([y], fs, window_s=0.2, min_plateau_s=0.5)
    assert det.count == 5
    for i, (a, b) in enumerate(det.spans):
        assert i * n_each <= a < b <= (i + 1) * n_each
        assert y[a:b] == pytest.approx(levels[i], abs=0)
    # A constant signal is one plateau; a very short one none.
    assert detect_plateaus([np.zeros(500)], fs).count == 1
    assert detect_plateaus([np.zeros(20)], fs).count == 0


def test_detector_ignores_a_spike_and_keeps_a_real_excursion():
    fs = 200.0
    rng = np.random.default_rng(4)
    y = np.repeat([0.0, 1.0, 0.0], 800) + rng.normal(scale=0.002, size=2400)
    spiky = y.copy()
    spiky[400:404] += 0.5  # a 20 ms spike inside the first plateau
    det = detect_plateaus([spiky], fs)
    assert det.count == 3
    assert not det.use[400:404].any()  # the spike samples are left out of the plateau
    # Two equal plateaus around a short excursion (load taken off and put back) stay two.
    z = np.concatenate([np.zeros(800), np.full(60, 1.0), np.zeros(800)]) + rng.normal(scale=0.002, size=1660)
    assert detect_plateaus([z], fs).count == 2


def test_step_statistic_and_spans():
    y = np.concatenate([np.zeros(10), np.ones(10)])
    D, scale = step_statistic(y, 4)
    assert D[10] == pytest.approx(1.0) and D[3] == 0.0 and D[16] == 0.0
    assert scale[10] == pytest.approx(np.sqrt(0.5))
    assert spans_from_mask([0, 1, 1, 0, 1]).tolist() == [[1, 3], [4, 5]]
    gaps = time_gaps(np.array([0, 0.1, 0.2, 0.5, 0.6]))
    assert len(gaps) == 1 and (gaps[0].t_start_s, gaps[0].t_end_s) == (0.2, 0.5)


def test_conversion_flags():
    v = np.array([0.0, 1.0, 7.995, 8.0, 9.0, np.nan, -8.0, 0.5])
    t = np.arange(v.size) * 0.1
    c = displacement_from_volts(v, t, scale_um_per_v=640, range_v=8, axis_sign=-1)
    assert c.displacement_mm[1] == pytest.approx(-0.640, abs=1e-15)
    assert c.saturated.tolist() == [False, False, True, True, False, False, True, False]
    assert c.out_of_range.tolist() == [False, False, False, False, True, False, False, False]
    assert c.missing.tolist() == [False] * 5 + [True, False, False]
    kinds = [(s.kind, s.start, s.stop) for s in c.spans]
    assert kinds == [("saturated", 2, 4), ("out of range", 4, 5), ("dropout", 5, 6), ("saturated", 6, 7)]
    with pytest.raises(ValueError, match="axis_sign must be"):
        displacement_from_volts(v, t, axis_sign=2)
