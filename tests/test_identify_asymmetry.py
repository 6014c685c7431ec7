"""The asymmetry test of an identified K holds its level when K's covariance is estimated.

The Wald statistic of K - K^T against a covariance estimated from few residual degrees of
freedom is not chi-square (issues 26/27); ``asymmetry_p_value`` refers it to Hotelling's law
with the effective degrees of freedom of ``asymmetry_dof``. Measured over 2000 trials a row in
``benchmarks/results/asymmetry.md``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from helpers.random_matrices import random_spd
from scipy import stats

from stiffmap.campaign.flags import FAMILY_ALPHA, _asymmetry_flags
from stiffmap.identify import (
    _asymmetry_map,
    _inverse_jacobian,
    asymmetry_dof,
    asymmetry_p_value,
    identify_stiffness,
)
from stiffmap.loads import forces_matrix, paper9
from stiffmap.stats import holm_rejects, hotelling_t2_sf

F9 = forces_matrix(paper9())


def _binomial_upper(n: int, p: float, tail: float = 1e-3) -> int:
    """The count a Binomial(n, p) exceeds with probability below ``tail``."""
    return int(stats.binom.isf(tail, n, p))


@pytest.mark.parametrize("nu", [3.0, 7.5, 40.0])
def test_hotelling_law_for_one_component_is_students_t(nu):
    # q = 1: T^2 = t^2 with t of Student's law with nu degrees of freedom (two-sided).
    t = np.array([0.5, 2.0, 4.0])
    np.testing.assert_allclose(hotelling_t2_sf(t**2, 1, nu), 2 * stats.t.sf(t, nu), rtol=1e-10)


def test_hotelling_law_known_covariance_and_too_few_dof():
    x = np.array([1.0, 9.0])
    np.testing.assert_allclose(hotelling_t2_sf(x, 3, np.inf), stats.chi2.sf(x, 3), rtol=1e-12)
    assert np.isnan(hotelling_t2_sf(5.0, 3, 2.5))  # fewer dof than dimensions: no law


def test_hotelling_law_matches_simulated_t2(rng):
    # T^2 = a^T S^-1 a, a ~ N(0, V), S the sample covariance of nu independent N(0, V) draws,
    # simulated here from its definition (q = 3, nu = 6).
    q, nu, n = 3, 6, 20000
    V = random_spd(rng, q, 1.0, 10.0)
    Lv = np.linalg.cholesky(V)
    a = rng.normal(size=(n, q)) @ Lv.T
    X = rng.normal(size=(n, nu, q)) @ Lv.T
    S = np.einsum("nki,nkj->nij", X, X) / nu
    t2 = np.einsum("ni,ni->n", a, np.linalg.solve(S, a[:, :, None])[:, :, 0])
    for level in (0.1, 0.01):
        c = stats.f.isf(level, q, nu - q + 1) * q * nu / (nu - q + 1)
        assert hotelling_t2_sf(c, q, nu) == pytest.approx(level, rel=1e-9)
        # Binomial band of 4.5 standard errors around the level.
        assert abs(np.mean(t2 > c) - level) < 4.5 * np.sqrt(level * (1 - level) / n)


@pytest.mark.parametrize("m", [3, 6])
def test_asymmetry_dof_matches_a_wishart_simulation(m, rng):
    # Sigma_hat ~ Wishart(Sigma, nu) / nu drawn here; V_hat = A J (Sigma_hat kron P) J^T A^T.
    # The effective dof is defined by E |V^-1/2 V_hat V^-1/2 - I|_F^2 = q (q + 1) / nu_e.
    nu, n = 9, 4000
    K = random_spd(rng, m, 2.0, 20.0)
    sigma = random_spd(rng, m, 0.5, 5.0)
    P = np.linalg.inv(random_spd(rng, m, 1.0, 30.0))
    G = _asymmetry_map(m) @ _inverse_jacobian(K)
    q = G.shape[0]
    K_cov = _inverse_jacobian(K) @ np.kron(sigma, P) @ _inverse_jacobian(K).T
    V = G @ np.kron(sigma, P) @ G.T
    Vi = np.linalg.inv(np.linalg.cholesky(V))
    X = rng.normal(size=(n, nu, m)) @ np.linalg.cholesky(sigma).T
    total = 0.0
    for S in np.einsum("nki,nkj->nij", X, X) / nu:
        E = Vi @ G @ np.kron(S, P) @ G.T @ Vi.T - np.eye(q)
        total += np.sum(E**2)
    nu_e = asymmetry_dof(K, K_cov, nu)
    assert q * (q + 1) / (total / n) == pytest.approx(nu_e, rel=0.05)
    assert nu_e >= nu  # one Wishart matrix spread over fewer independent dimensions


def _trials(rng, K, F, noise_root, n: int):
    """(new p, chi-square p, flagged by identify_stiffness) over n noisy identifications."""
    D0 = np.linalg.solve(K, F)
    out = []
    for _ in range(n):
        fit = identify_stiffness(F, D0 + noise_root @ rng.normal(size=D0.shape), offset=True)
        out.append(
            (
                fit.asymmetry_p,
                asymmetry_p_value(fit.K, fit.K_cov),
                any(f.startswith("asymmetric") for f in fit.flags),
            )
        )
    return np.array(out)


def test_false_alarms_hold_their_level_where_chi_square_does_not(rng):
    # A campaign position: the paper's nine loads once against the mean reference (offset,
    # 5 residual dof), noise correlated between axes (0.6), a symmetric K.
    K = random_spd(rng, 3, 2.0, 20.0)
    s = 0.005 * np.abs(np.linalg.solve(K, F9)).max()
    L = np.linalg.cholesky(s**2 * (np.full((3, 3), 0.6) + 0.4 * np.eye(3)))
    n = 300
    p_new, p_chi2, flagged = _trials(rng, K, F9, L, n).T
    # At 1 %: no more than a Binomial(300, 1 %) exceeds with probability 1e-3 ...
    assert flagged.sum() <= _binomial_upper(n, 0.01)
    assert np.sum(p_new < 0.01) == flagged.sum()  # identify_stiffness's flag is this test
    fit = identify_stiffness(F9, np.linalg.solve(K, F9) + L @ rng.normal(size=F9.shape), offset=True)
    assert fit.asymmetry_p == asymmetry_p_value(fit.K, fit.K_cov, 5) and fit.cov_dof == 5
    # ... and p-values uniform at 10 % on both sides (too conservative fails too).
    assert _binomial_upper(n, 0.1, 1 - 1e-3) <= np.sum(p_new < 0.1) <= _binomial_upper(n, 0.1)
    # The chi-square law the test used before: several times its 1 % level (8 % in the benchmark).
    assert np.sum(p_chi2 < 0.01) > _binomial_upper(n, 0.02)


def test_power_on_an_asymmetric_K(rng):
    # The paper's nine loads twice against the mean reference (14 dof): K asymmetric by 5 %
    # (|K - K^T| / |K|), noise 0.5 % of the largest displacement: flagged in nearly every trial
    # (100 % of 2000 in the benchmark; at 2 %: 85 % here, 39 % there, the power depending on
    # the direction of the asymmetry).
    K = random_spd(rng, 3, 2.0, 20.0)
    N = np.array([[0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [1.0, -1.0, 0.0]]) / np.sqrt(6)
    Ka = K + 0.05 * np.linalg.norm(K) / np.sqrt(4 - 0.05**2) * N
    F = np.tile(F9, 2)
    s = 0.005 * np.abs(np.linalg.solve(K, F)).max()
    p_new, _, flagged = _trials(rng, Ka, F, s * np.eye(3), 60).T
    assert flagged.mean() >= 0.95


def test_a_given_covariance_keeps_the_chi_square_law(rng):
    # Known displacement covariance: T^2 is chi-square of 3 (computed here from the fit).
    K = random_spd(rng, 3, 2.0, 20.0)
    D = np.linalg.solve(K, F9) + rng.normal(scale=2e-3, size=F9.shape)
    fit = identify_stiffness(F9, D, disp_cov=np.full(F9.shape, 2e-3))
    A = _asymmetry_map(3)
    a = A @ fit.K.ravel()
    t2 = a @ np.linalg.solve(A @ fit.K_cov @ A.T, a)
    assert asymmetry_p_value(fit.K, fit.K_cov) == pytest.approx(stats.chi2.sf(t2, 3), rel=1e-10)
    assert asymmetry_p_value(fit.K, fit.K_cov, np.inf) == pytest.approx(stats.chi2.sf(t2, 3), rel=1e-10)
    assert fit.cov_dof is None and fit.asymmetry_p == pytest.approx(stats.chi2.sf(t2, 3), rel=1e-10)


def test_a_symmetric_K_is_not_tested_against_its_covariance(rng):
    fit = identify_stiffness(F9, np.linalg.solve(random_spd(rng, 3, 2.0, 20.0), F9) + 1e-3, method="spd")
    assert asymmetry_p_value(fit.K, fit.K_cov, fit.dof) == 1.0


def test_a_campaign_of_symmetric_positions_raises_no_asymmetry_failure(rng):
    # Six simulated campaigns of 48 positions (the reference study's map), each K symmetric,
    # identified as the runner does (paper9 once against the mean reference: 5 residual dof,
    # noise 0.5 % of the largest displacement, correlated 0.6 between axes). Holm's test at 1 %
    # over the positions (campaign.flags) flags a family-wise 1 %: at most one campaign of
    # six (probability 1.5e-3 at 1 %). With the chi-square law it flagged most campaigns (8 of
    # 10 over three seeds): the smallest Holm threshold, 1 % / 48, is exceeded about 3.5 % of
    # the time per position.
    flagged_new = flagged_old = 0
    for _ in range(6):
        rows, p_old = [], []
        for pos in range(48):
            K = random_spd(rng, 3, 2.0, 20.0)
            s = 0.005 * np.abs(np.linalg.solve(K, F9)).max()
            L = np.linalg.cholesky(s**2 * (np.full((3, 3), 0.6) + 0.4 * np.eye(3)))
            fit = identify_stiffness(F9, np.linalg.solve(K, F9) + L @ rng.normal(size=F9.shape), offset=True)
            rows.append(
                SimpleNamespace(position=pos, K=fit.K, K_cov=fit.K_cov, dof=fit.dof, K_cov_calibration=None)
            )
            p_old.append(asymmetry_p_value(fit.K, fit.K_cov))
        flagged_new += bool(_asymmetry_flags(rows))
        flagged_old += bool(holm_rejects(np.array(p_old), FAMILY_ALPHA).any())
    assert flagged_new <= 1
    assert flagged_old >= 3


@pytest.mark.parametrize("offset", [False, True])
def test_noise_free_data_with_a_common_error_is_not_an_overflow(offset):
    # Exact displacements of an asymmetric K (8.5 %) with a common scale error given: K - K^T's
    # covariance is the common share's, of rank 1 (singular). The test is then not made (p NaN)
    # and the fixed 10 % threshold decides, as for any singular covariance; the effective-dof
    # computation once divided by the zero noise and identify_stiffness reported "no finite
    # stiffness ... beyond floating-point range".
    K = np.array([[6.0, 1.0, 0.0], [0.3, 4.0, 0.5], [0.0, 0.5, 9.0]])
    F = np.hstack([2 * np.eye(3), 4 * np.eye(3), -2 * np.eye(3)])
    D = np.linalg.solve(K, F)
    fit = identify_stiffness(F, D, offset=offset, common_jacobian=D.T[:, :, None], common_cov=[[1e-6]])
    assert np.isnan(fit.asymmetry_p) and not any(f.startswith("asymmetric") for f in fit.flags)
    np.testing.assert_allclose(fit.K, K, atol=1e-9)  # N/mm


@pytest.mark.parametrize("t", [1e-3, 1e3])
def test_6x6_test_does_not_depend_on_the_units(t, rng):
    # Moments in N m instead of N mm (or the reverse) and rotations in mrad (or krad):
    # F' = T F, D' = T^-1 D, K' = T K T keeps K's symmetry and the test's p-value (a Wald
    # statistic and a Satterthwaite dof are invariant under a change of parameters), though
    # K - K^T's variances then span 1e12 or more.
    Z = np.zeros((3, 3))
    K = np.block([[random_spd(rng, 3, 2.0, 20.0), Z], [Z, random_spd(rng, 3, 2e4, 2e5)]])
    W = np.diag([5.0, 5.0, 5.0, 500.0, 500.0, 500.0])
    F = np.tile(np.hstack([W, -W]), 2)
    D0 = np.linalg.solve(K, F)
    E = 0.005 * np.abs(D0).max(axis=1, keepdims=True) * rng.normal(size=D0.shape)
    # An asymmetry of the coupling of one standard error of K[0, 4] - K[4, 0] (N).
    cov = identify_stiffness(F, D0 + E).K_cov
    K[0, 4] += np.sqrt(cov[4, 4] + cov[24, 24] - 2 * cov[4, 24])
    D = np.linalg.solve(K, F) + E
    T = np.diag([1.0, 1.0, 1.0, t, t, t])
    a, b = identify_stiffness(F, D), identify_stiffness(T @ F, np.linalg.solve(T, D))
    assert 1e-3 < a.asymmetry_p < 0.9  # tested (not the singular covariance's 0 or 1)
    assert b.asymmetry_p == pytest.approx(a.asymmetry_p, rel=1e-6)
    assert asymmetry_dof(b.K, b.K_cov, b.dof) == pytest.approx(asymmetry_dof(a.K, a.K_cov, a.dof), rel=1e-6)


def test_a_copied_design_is_not_tested(rng):
    # Four load cases written twice (5 residual dof, but the residuals come in equal pairs):
    # Sigma_hat is of rank 1 and K - K^T's covariance singular. The p-value is NaN (not a
    # sentinel 0 that Holm's test would count as a rejection) and the 10 % threshold decides.
    K = random_spd(rng, 3, 1.0, 10.0)
    K[1, 2] += 0.2 * np.linalg.norm(K)
    F = np.tile(F9[:, :4], 2)
    D = np.linalg.solve(K, F) + np.tile(rng.normal(scale=1e-3, size=(3, 4)), 2)
    fit = identify_stiffness(F, D)
    assert fit.dof == 5 and np.isnan(fit.asymmetry_p)
    assert [f for f in fit.flags if f.startswith("asymmetric")] == [
        f"asymmetric: |K-K^T|/|K| = {fit.indices.asymmetry:.3g} > 0.1"
    ]
    rows = [SimpleNamespace(position=1, K=fit.K, K_cov=fit.K_cov, dof=fit.dof, K_cov_calibration=None)]
    assert _asymmetry_flags(rows)[1][1] is False  # a review flag, not a tested failure
