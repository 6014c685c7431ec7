"""A campaign's robot whose platform turns: the K of hung forces, legs fitted to 6-DOF displacements."""

from __future__ import annotations

from importlib.resources import files

import numpy as np
import pytest

from stiffmap.campaign.platform import fit_platform, hung_force_stiffness, is_platform, level_poses
from stiffmap.models.legs import LegRobot

K_TRUE = {"k_leg1": 9.0, "k_leg2": 7.5, "k_leg3": 11.0, "k_leg4": 8.0, "k_leg5": 10.5, "k_leg6": 12.0}


@pytest.fixture(scope="module")
def hexapod():
    return LegRobot.from_toml(files("stiffmap.models") / "robots" / "hexapod.toml").with_params(**K_TRUE)


def test_hung_forces_see_the_tool_point_move_by_the_wrenchs_translation(hexapod):
    K6 = hexapod.stiffness6([10.0, -5.0, 310.0, 0.0, 0.0, 0.0])
    r = np.array([30.0, -70.0, -120.0])
    K = hung_force_stiffness(K6, r)
    for F in np.eye(3) * 5.0:
        u = np.linalg.solve(K6, np.r_[F, np.cross(r, F)])[:3]
        np.testing.assert_allclose(np.linalg.solve(K, F), u, rtol=1e-10)
    C = np.linalg.inv(K6)  # at the tool point: the pure force's K
    np.testing.assert_allclose(hung_force_stiffness(K6, np.zeros(3)), np.linalg.inv(C[:3, :3]), rtol=1e-12)
    assert is_platform(hexapod)
    assert not is_platform(LegRobot.from_toml(files("stiffmap.models") / "robots" / "delta.toml"))


def test_fit_platform_recovers_the_legs_from_noisy_6dof_displacements(hexapod):
    # paper9-like loads (0.5 kg along +y, -x, -z) hung 80 mm below the tool point at nine level
    # positions; the displacements K6^-1 (F, r x F) with 2 um and 20 urad of noise.
    P = np.array([[x, y, 300.0] for x in (-40.0, 0.0, 40.0) for y in (-40.0, 0.0, 40.0)])
    r = np.array([0.0, 0.0, -80.0])
    F = 4.905 * np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    K6 = hexapod.stiffness6(level_poses(P))
    idx = np.repeat(np.arange(len(P)), 3)
    forces = np.tile(F, (len(P), 1))
    D = np.array([np.linalg.solve(K6[i], np.r_[f, np.cross(r, f)]) for i, f in zip(idx, forces, strict=True)])
    sd = np.array([2e-3, 2e-3, 2e-3, 2e-5, 2e-5, 2e-5])
    D += sd * np.random.default_rng(5).normal(size=D.shape)
    cov = np.tile(np.diag(sd**2), (len(D), 1, 1))
    start = hexapod.with_params(**dict.fromkeys(K_TRUE, 10.0))
    f = fit_platform(start, P, idx, forces, r, D, cov, tuple(K_TRUE))
    k = np.array(list(K_TRUE.values()))
    assert np.all(np.abs(f.estimate - k) < 4 * f.std), (f.estimate, f.std)
    assert np.all(f.std < 0.01 * k)


def test_fit_platform_whitens_by_the_full_covariance_and_says_the_extra_noise(hexapod):
    # A camera-like covariance (dx-rz correlation -0.95) that is too small along its
    # near-degenerate direction: the noise drawn has 0.5 um and 5 urad more per axis.
    P = np.array([[x, y, 300.0] for x in (-40.0, 40.0) for y in (-40.0, 40.0)])
    r = np.array([0.0, 0.0, -100.0])
    F = 4.905 * np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    idx = np.repeat(np.arange(len(P)), 3 * 6)
    forces = np.tile(F, (6 * len(P), 1))
    K6 = hexapod.stiffness6(level_poses(P))
    D = np.array([np.linalg.solve(K6[i], np.r_[f, np.cross(r, f)]) for i, f in zip(idx, forces, strict=True)])
    sd = np.array([2e-3, 2e-3, 2e-3, 2e-5, 2e-5, 2e-5])
    R = np.eye(6)
    R[0, 5] = R[5, 0] = -0.95
    cov = np.tile(R * np.outer(sd, sd), (len(D), 1, 1))
    extra = np.diag(np.r_[3 * [5e-4], 3 * [5e-6]] ** 2)
    rng = np.random.default_rng(8)
    D += rng.normal(size=D.shape) @ np.linalg.cholesky(cov[0] + extra).T
    start = hexapod.with_params(**dict.fromkeys(K_TRUE, 10.0))
    f = fit_platform(start, P, idx, forces, r, D, cov, tuple(K_TRUE))
    k = np.array(list(K_TRUE.values()))
    assert np.all(np.abs(f.estimate - k) < 4 * f.std), (f.estimate, f.std)
    # The extra noise is information (a campaign prints it as a note, exit 0), not a problem:
    assert len(f.info) == 1 and "extra noise" in f.info[0] and "mrad" in f.info[0], f.info
    assert not f.notes, f.notes  # the chi2 misfit note is replaced
    # The fit before issue 30, each component alone: chi2 = sum of (r / std)^2, written here.
    d = fit_platform(start, P, idx, forces, r, D, cov, tuple(K_TRUE), correlated=False, extra_noise=False)
    W = np.concatenate([forces, np.cross(r, forces)], axis=1)
    res = D - np.linalg.solve(d.model.stiffness6(level_poses(P))[idx], W[..., None])[..., 0]
    assert d.chi2 == pytest.approx(float(np.sum(res**2 / sd**2)), rel=1e-9)
    assert d.extra_covariance is None
