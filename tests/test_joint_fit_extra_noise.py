"""The extra translation noise of ``fit_joint_compliances(extra_noise=True)``, and when none will do.

The extra noise is added to the translations only. When the displacements' rotations scatter
more than their covariances say, no amount of it brings chi2/dof to 1: the search used to grow
the variance by 4 for ever, until it overflowed into "cov: row 0 contains NaN or infinite
values". It is bounded now, and such data are fitted with their own covariances and a note
saying why.

The design: a six-joint arm's Jacobians drawn at random (translations in mm/rad from joints
about 500 mm from the measured point, rotations in rad/rad), loads of 50 N at 100 mm.
"""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.models import fit_joint_compliances, joint_deflections

K_TRUE = np.array([2.0e7, 1.5e7, 1.0e7, 4.0e6, 3.0e6, 2.0e6])  # N*mm/rad
SIGMA = np.array([1e-3] * 3 + [1e-5] * 3)  # 1 um, 10 urad


def _design(seed: int, configs: int = 6, loads: int = 6):
    rng = np.random.default_rng(seed)
    J = np.empty((configs, 6, 6))
    J[:, :3] = rng.normal(0.0, 500.0, (configs, 3, 6))
    J[:, 3:] = rng.normal(0.0, 1.0, (configs, 3, 6))
    F = rng.normal(0.0, 50.0, (loads, 3))
    r = rng.normal(0.0, 100.0, (loads, 3))
    W = np.concatenate([F, np.cross(r, F)], axis=1)
    Jr = np.repeat(J, loads, axis=0)
    Wr = np.tile(W, (configs, 1))
    cfg = np.repeat(np.arange(configs), loads)
    D = joint_deflections(Jr, Wr, 1.0 / K_TRUE)
    cov = np.broadcast_to(np.diag(SIGMA**2), (len(D), 6, 6)).copy()
    return Jr, Wr, D, cov, cfg, rng


def test_a_misfit_in_the_rotations_is_said_not_an_overflow():
    J, W, D, cov, cfg, rng = _design(1)
    D[:, 3:] += rng.normal(0.0, 100 * SIGMA[3], (len(D), 3))  # rotations 100 times noisier than said
    D[:, :3] += rng.normal(0.0, SIGMA[0], (len(D), 3))
    fit = fit_joint_compliances(J, W, D, cov, config_index=cfg, extra_noise=True)
    note = fit.notes[-1]
    assert "no extra translation noise explains it" in note and "the rotations' misfit" in note
    assert fit.extra_translation_std == 0.0
    # The fit with the given covariances, its standard errors scaled by the scatter.
    plain = fit_joint_compliances(J, W, D, cov, config_index=cfg)
    np.testing.assert_array_equal(fit.compliance, plain.compliance)
    np.testing.assert_array_equal(fit.covariance, plain.covariance)
    assert np.all(np.isfinite(fit.stiffness_std)) and plain.reduced_chi2 > 1e3


@pytest.mark.parametrize("extra_um", [5.0, 50.0])
def test_a_misfit_in_the_translations_is_an_extra_noise_that_makes_chi2_one(extra_um):
    J, W, D, cov, cfg, rng = _design(2)
    D[:, :3] += rng.normal(0.0, extra_um * 1e-3, (len(D), 3))
    D[:, 3:] += rng.normal(0.0, SIGMA[3], (len(D), 3))
    fit = fit_joint_compliances(J, W, D, cov, config_index=cfg, extra_noise=True)
    assert fit.reduced_chi2 == pytest.approx(1.0, abs=1e-4)
    # The noise found is the one added, within its sampling scatter (108 rows x 3 axes).
    assert fit.extra_translation_std * 1e3 == pytest.approx(extra_um, rel=0.25)
    assert "extra translation noise (robot jitter, vibration) was added" in fit.info[-1]
    assert not any("extra translation noise" in n for n in fit.notes)  # information, not a problem
