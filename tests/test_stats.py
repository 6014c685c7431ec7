"""ISO 5725-2 repeat statistics: critical values and the precision analysis."""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.stats import (
    cochran_critical,
    describe,
    excess_dispersion,
    grubbs_critical,
    mandel_h_critical,
    mandel_k_critical,
    precision,
)

# ISO 5725-2:1994 Tables 4-6 (and the list) for p = 8 laboratories, n = 2 repeats,
# 5 % (stragglers) and 1 % (outliers). Printed to 3 decimals: compare to half a unit.
PUBLISHED = {
    "h": (1.749, 2.065),
    "k": (1.885, 2.256),
    "C": (0.680, 0.794),
    "G": (2.127, 2.274),
}
TOL = 6e-4


@pytest.mark.parametrize("i, alpha", [(0, 0.05), (1, 0.01)])
def test_critical_values_match_iso_5725_2_tables(i, alpha):
    assert mandel_h_critical(8, alpha) == pytest.approx(PUBLISHED["h"][i], abs=TOL)
    assert mandel_k_critical(8, 2, alpha) == pytest.approx(PUBLISHED["k"][i], abs=TOL)
    assert cochran_critical(8, 2, alpha) == pytest.approx(PUBLISHED["C"][i], abs=TOL)
    assert grubbs_critical(8, alpha) == pytest.approx(PUBLISHED["G"][i], abs=TOL)


def test_grubbs_critical_stays_below_the_largest_possible_statistic():
    # No sample of p values has G above (p - 1)/sqrt(p); for p = 3 the critical values
    # crowd against that bound (1.1547).
    for p in (3, 4, 8, 20):
        bound = (p - 1) / np.sqrt(p)
        for alpha in (0.05, 0.01):
            assert grubbs_critical(p, alpha) < bound
    assert grubbs_critical(3, 0.05) > 1.154


def test_critical_values_grow_with_confidence():
    for p in (3, 5, 10, 30):
        assert mandel_h_critical(p, 0.01) > mandel_h_critical(p, 0.05)
        assert grubbs_critical(p, 0.01) > grubbs_critical(p, 0.05)
        assert cochran_critical(p, 4, 0.01) > cochran_critical(p, 4, 0.05)
        assert mandel_k_critical(p, 4, 0.01) > mandel_k_critical(p, 4, 0.05)


def test_precision_recovers_known_repeatability_and_between_spread():
    rng = np.random.default_rng(5725)
    s_r, s_L = 0.02, 0.05  # mm
    groups = [rng.normal(10 + rng.normal(scale=s_L), s_r, size=5) for _ in range(400)]
    res = precision(groups)
    assert res.s_r == pytest.approx(s_r, rel=0.05)
    assert res.s_L == pytest.approx(s_L, rel=0.1)
    assert res.r == pytest.approx(2.8 * res.s_r)
    assert res.R == pytest.approx(2.8 * np.hypot(res.s_L, res.s_r))
    assert res.grand_mean == pytest.approx(10.0, abs=0.01)


def test_precision_flags_an_outlying_mean_and_a_noisy_condition():
    rng = np.random.default_rng(1)
    groups = [list(rng.normal(5.0, 0.01, size=4)) for _ in range(8)]
    groups[3] = [x + 0.2 for x in groups[3]]  # a shifted condition: 20 sigma
    groups[6] = list(rng.normal(5.0, 0.2, size=4))  # a noisy condition
    res = precision(groups, labels=[f"position {i + 1}" for i in range(8)])
    text = " | ".join(res.outliers + res.stragglers)
    assert "position 4: Grubbs" in text or "position 4: Mandel h" in text
    assert "position 7: Cochran" in text or "position 7: Mandel k" in text
    assert res.cochran_C > res.critical["C"][1]


def test_mandel_h_sums_to_zero_and_k_mean_square_is_one():
    rng = np.random.default_rng(2)
    groups = [rng.normal(size=3) for _ in range(6)]
    res = precision(groups)
    assert res.h.sum() == pytest.approx(0.0, abs=1e-12)
    assert np.mean(res.k**2) == pytest.approx(1.0, rel=1e-12)


def test_unequal_repeats_use_the_iso_nbar():
    groups = [[1.0, 1.1, 0.9], [2.0, 2.2], [1.5, 1.4, 1.6, 1.5]]
    res = precision(groups)
    n = np.array([3, 2, 4])
    means = np.array([np.mean(g) for g in groups])
    s2 = np.array([np.var(g, ddof=1) for g in groups])
    s_r2 = ((n - 1) * s2).sum() / (n - 1).sum()
    grand = (n * means).sum() / n.sum()
    s_d2 = (n * (means - grand) ** 2).sum() / 2
    nbar = (n.sum() - (n**2).sum() / n.sum()) / 2
    assert res.s_r == pytest.approx(np.sqrt(s_r2), rel=1e-12)
    assert res.s_L == pytest.approx(np.sqrt((s_d2 - s_r2) / nbar), rel=1e-12)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="at least 2 repeats"):
        precision([[1.0, 2.0], [3.0]], labels=["a", "b"])
    with pytest.raises(ValueError, match="NaN"):
        describe([1.0, float("nan")])
    with pytest.raises(ValueError, match="p"):
        mandel_h_critical(2, 0.05)


# ------------------------------------------------------------------ excess dispersion
def _draws(rng, n: int, D: np.ndarray):
    """n vectors e_i ~ N(0, P_i + D) with P_i of random shapes and scales (a factor 10 apart)."""
    p = len(D)
    P = []
    for _ in range(n):
        A = rng.normal(size=(p, p))
        P.append((A @ A.T / p + 0.1 * np.eye(p)) * 10 ** rng.uniform(-0.5, 0.5))
    P = np.array(P)
    e = np.array([rng.multivariate_normal(np.zeros(p), Pi + D) for Pi in P])
    return e, P


def test_excess_dispersion_recovers_a_known_excess():
    """Seeded draws with D known: the estimate within its sampling error (n = 2000, a few %)."""
    rng = np.random.default_rng(11)
    L = rng.normal(size=(4, 4))
    D = L @ L.T
    e, P = _draws(rng, 2000, D)
    r = excess_dispersion(e, P)
    assert r.p_value < 1e-10 and r.left_out == ()
    # Relative to D's scale: sampling error of a second moment over 2000 draws ~ 3-5 %.
    assert np.abs(r.cov - D).max() < 0.12 * np.abs(D).max(), (r.cov, D)
    # The variance ratio is (trace-wise) above 1: sum e P^-1 e / (p (n - 1)).
    expected = np.mean([np.trace(np.linalg.solve(Pi, Pi + D)) for Pi in P]) / 4
    assert r.ratio == pytest.approx(expected, rel=0.1)


def test_excess_dispersion_is_zero_when_the_covariances_hold():
    """Vectors drawn with their own covariances: D = 0 in about 95 % of sets (the 5 % test)."""
    rng = np.random.default_rng(12)
    zero = 0
    for _ in range(100):
        e, P = _draws(rng, 13, np.zeros((6, 6)))
        r = excess_dispersion(e, P)
        zero += not np.any(r.cov)
        assert np.all(np.linalg.eigvalsh(r.cov) > -1e-12)  # positive semi-definite
    # Binomial(100, 0.95): 89..99 at 99.9 %.
    assert zero >= 88, zero


def test_one_gross_bad_vector_is_left_out():
    """13 vectors of 6 with a known excess, one shifted by 40 sigma: left out, D from the others."""
    rng = np.random.default_rng(13)
    D = np.diag([4.0, 1.0, 1.0, 0.5, 0.5, 0.5])
    e, P = _draws(rng, 13, D)
    clean = excess_dispersion(e, P)
    e_bad = e.copy()
    e_bad[5] += 40.0 * np.sqrt(np.diag(P[5] + D))
    r = excess_dispersion(e_bad, P)
    assert r.left_out == (5,)
    without = excess_dispersion(np.delete(e, 5, axis=0), np.delete(P, 5, axis=0))
    np.testing.assert_allclose(r.cov, without.cov, rtol=1e-12, atol=1e-12)
    # Kept, it would have inflated D's largest variance many times over.
    kept = excess_dispersion(e_bad, P, outlier_quantile=1.0)
    assert np.linalg.eigvalsh(kept.cov).max() > 10 * np.linalg.eigvalsh(clean.cov).max()
    with pytest.raises(ValueError, match="covs must be"):
        excess_dispersion(e, P[:, :5, :5])


def test_holm_rejects_by_adjusted_p_values_computed_here():
    """Holm (1979): reject H_(k) when max_{j<=k} (m - j) p_(j) < alpha. The adjusted p-values are
    computed here from that definition (an independent route from the step-down loop), over
    random families with NaN (untested) members; and Holm's textbook case: 0.005, 0.01 rejected
    at 5 % of (0.01, 0.04, 0.03, 0.005), 0.03 not (0.03 > 0.05/2)."""
    from stiffmap.stats import holm_rejects

    assert holm_rejects([0.01, 0.04, 0.03, 0.005], 0.05).tolist() == [True, False, False, True]
    rng = np.random.default_rng(7)
    for _ in range(200):
        p = rng.uniform(0, 0.05, rng.integers(1, 12)) ** rng.uniform(0.5, 3)
        p[rng.random(p.size) < 0.2] = np.nan
        ok = np.isfinite(p)
        m = int(ok.sum())
        adj = np.full(p.size, np.inf)
        order = np.flatnonzero(ok)[np.argsort(p[ok])]
        running = 0.0
        for k, i in enumerate(order):
            running = max(running, (m - k) * p[i])
            adj[i] = running
        assert np.array_equal(holm_rejects(p, 0.01), adj < 0.01)
    # A family of 48 with the smallest p = 0.0011 (the demo's): nothing rejected at 1 %.
    assert not holm_rejects(np.r_[0.0011, 0.006, 0.0064, np.linspace(0.02, 1, 45)], 0.01).any()
