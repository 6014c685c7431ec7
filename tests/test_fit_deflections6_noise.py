"""``fit_deflections6`` with full 6 x 6 covariances and an estimated extra noise (issue 30).

A camera's 6-DOF displacement has strongly correlated components (its translation along the
line of sight and its rotation across it: correlation about -0.95), and its stated covariance
is too small in the near-degenerate direction that correlation leaves. The fit whitens each
deflection by the Cholesky factor of its covariance, and with ``extra_noise`` estimates the
6 x 6 noise X the stated covariances leave out.

The problems here are drawn in the test: six springs (a hexapod's legs: K6 = sum k_i a_i a_i^T,
a_i = (n_i, r_i x n_i), written here, not through stiffmap's legs) at a few poses, wrenches
(F, r x F) of 5 N loads hung about 100 mm away, the deflections K6^-1 w plus noise drawn from
the true covariance C_m + X, X drawn by the test.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib.resources import files
from types import SimpleNamespace

import numpy as np
import pytest

from stiffmap.errors import InputError
from stiffmap.models.fit import fit_deflections6
from stiffmap.models.legs import LegRobot

K_TRUE = np.array([9.0, 7.5, 11.0, 8.0, 10.5, 12.0])  # N/mm
NAMES = tuple(f"k{i}" for i in range(1, 7))
SD = np.array([2e-3, 2e-3, 2e-3, 2e-5, 2e-5, 2e-5])  # 2 um, 20 urad


@dataclass(frozen=True)
class Springs6:
    """Six springs along wrench directions a_i at each pose: K6 = sum_i k_i a_i a_i^T (pose i
    is the one whose x is i)."""

    A: np.ndarray  # (poses, 6 springs, 6)
    k: tuple = tuple(K_TRUE)
    name: str = "springs6"
    dim: int = 6
    length_mm: float = 100.0
    _cache: dict = field(default_factory=dict, compare=False)

    def params(self) -> dict[str, float]:
        return dict(zip(NAMES, self.k, strict=True))

    def with_params(self, **kw):
        p = self.params() | kw
        return Springs6(self.A, tuple(p[n] for n in NAMES))

    def evaluate(self, P):
        A = self.A[np.asarray(P)[:, 0].astype(int)]
        K6 = np.einsum("l,pla,plb->pab", np.array(self.k), A, A)
        return SimpleNamespace(K6=K6, valid=np.ones(len(A), bool), reasons=[""] * len(A))


def _stated_covariance() -> np.ndarray:
    """A camera-like covariance: dx-rz correlation -0.95, dy-rx +0.9 (L = 100 mm)."""
    R = np.eye(6)
    R[0, 5] = R[5, 0] = -0.95
    R[1, 3] = R[3, 1] = 0.9
    return R * np.outer(SD, SD)


def _problem(rng, poses: int, loads: int, repeats: int):
    """Springs at ``poses`` poses, ``loads`` wrenches each, ``repeats`` times: the mechanism,
    the poses, the wrenches, the exact deflections and the stated covariances (each the
    camera-like one scaled by a factor in [0.5, 2])."""
    n = rng.normal(size=(poses, 6, 3))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    r = rng.normal(0.0, 100.0, (poses, 6, 3))
    model = Springs6(np.concatenate([n, np.cross(r, n)], axis=2))
    F = rng.normal(0.0, 5.0, (loads, 3))
    lever = rng.normal(0.0, 100.0, (loads, 3))
    W = np.tile(np.concatenate([F, np.cross(lever, F)], axis=1), (poses * repeats, 1))
    P = np.zeros((len(W), 6))
    P[:, 0] = np.repeat(np.arange(poses), loads * repeats)
    K6 = model.evaluate(P).K6
    D = np.linalg.solve(K6, W[..., None])[..., 0]
    C = _stated_covariance() * rng.uniform(0.5, 2.0, len(W))[:, None, None]
    return model, P, W, D, C


def _draw_extra(rng) -> np.ndarray:
    """A rank-2 extra noise about as large as the stated one, most of it where that is small."""
    G = rng.normal(size=(6, 2)) * SD[:, None]
    return G @ G.T


def _noisy(rng, D, C, X):
    L = np.linalg.cholesky(C + X)
    return D + np.einsum("mab,mb->ma", L, rng.normal(size=D.shape))


def _mahalanobis_sum(r, C):
    return float(np.einsum("ma,ma->", r, np.linalg.solve(C, r[..., None])[..., 0]))


def test_full_covariances_weigh_the_fit_chi2_is_the_mahalanobis_sum():
    rng = np.random.default_rng(1)
    model, P, W, D, C = _problem(rng, poses=4, loads=6, repeats=2)
    Dn = _noisy(rng, D, C, 0.0)
    start = model.with_params(**dict.fromkeys(NAMES, 10.0))
    f = fit_deflections6(start, P, W, Dn, params=NAMES, cov=C)
    r = Dn - np.linalg.solve(f.model.evaluate(P).K6, W[..., None])[..., 0]
    assert f.chi2 == pytest.approx(_mahalanobis_sum(r, C), rel=1e-9)
    assert f.extra_covariance is None
    # Each component weighed alone (std): another minimum, of the diagonal's chi2, which the
    # full fit's Mahalanobis sum is below.
    d = fit_deflections6(start, P, W, Dn, params=NAMES, std=np.sqrt(np.einsum("mii->mi", C)))
    rd = Dn - np.linalg.solve(d.model.evaluate(P).K6, W[..., None])[..., 0]
    assert d.chi2 == pytest.approx(float(np.sum(rd**2 / np.einsum("mii->mi", C))), rel=1e-9)
    assert _mahalanobis_sum(rd, C) > f.chi2 * (1 + 1e-6)


def test_the_extra_noise_is_recovered_within_its_sampling_error():
    rng = np.random.default_rng(2)
    model, P, W, D, C = _problem(rng, poses=6, loads=9, repeats=8)
    X = _draw_extra(rng)
    Dn = _noisy(rng, D, C, X)
    start = model.with_params(**dict.fromkeys(NAMES, 10.0))
    f = fit_deflections6(start, P, W, Dn, params=NAMES, cov=C, extra_noise=True)
    # The moment estimate's sampling error, entry by entry, in units of the mean stated
    # covariance (Gaussian noise: var(e_i e_j) = S_ii S_jj + S_ij^2 with S = C_m + X).
    Lb = np.linalg.cholesky(C.mean(axis=0))
    white = np.linalg.solve(Lb, np.linalg.solve(Lb, np.swapaxes(C + X, 1, 2)).swapaxes(1, 2))
    dg = np.einsum("mii->mi", white)
    var = (np.einsum("mi,mj->ij", dg, dg) + np.sum(white**2, axis=0)) / len(C) ** 2
    err = np.linalg.solve(Lb, np.linalg.solve(Lb, f.extra_covariance - X).T)
    assert np.linalg.norm(err) < 3.0 * np.sqrt(var.sum()), (np.linalg.norm(err), np.sqrt(var.sum()))
    assert np.all(np.linalg.eigvalsh(f.extra_covariance) > -1e-12 * np.trace(X))
    assert f.reduced_chi2 == pytest.approx(1.0, abs=0.15)
    assert "extra noise" in f.info[0] and "mrad" in f.info[0] and not f.notes
    assert f.to_dict()["extra_std"] is not None


def test_no_extra_noise_when_the_covariances_are_right():
    rng = np.random.default_rng(3)
    model, P, W, D, C = _problem(rng, poses=6, loads=9, repeats=4)
    f = fit_deflections6(model, P, W, _noisy(rng, D, C, 0.0), params=NAMES, cov=C, extra_noise=True)
    Lb = np.linalg.cholesky(C.mean(axis=0))
    excess = np.linalg.eigvalsh(np.linalg.solve(Lb, np.linalg.solve(Lb, f.extra_covariance).T))
    # Only sampling noise is left: relative excess of the order of sqrt(2 / n) at most.
    assert excess.max() < 4.0 * np.sqrt(2.0 / len(C)), excess


@pytest.mark.slow
@pytest.mark.parametrize("extra", [True, False])
def test_z_scores_over_many_draws_are_standard_normal(extra):
    # One design, the noise and the extra noise drawn again each time; the extra noise (drawn
    # once) is left out of the stated covariances. z = (estimate - truth) / reported std.
    rng = np.random.default_rng(4)
    model, P, W, D, C = _problem(rng, poses=4, loads=9, repeats=2)
    X = _draw_extra(rng) * 4.0
    z = []
    for _ in range(60):
        Dn = _noisy(rng, D, C, X)
        f = fit_deflections6(model, P, W, Dn, params=NAMES, cov=C, extra_noise=extra)
        z.append((f.estimate - K_TRUE) / f.std)
    z = np.array(z)
    rms = float(np.sqrt(np.mean(z**2)))
    if extra:
        assert abs(rms - 1.0) < 0.12, rms  # 360 z: RMS within about 2.5 of its sampling error
        assert np.all(np.abs(z.mean(axis=0)) < 4.0 / np.sqrt(len(z))), z.mean(axis=0)
    else:  # the stated covariances alone, scaled by chi2/dof: the standard errors are wrong
        assert abs(rms - 1.0) > 0.2, rms


def test_bad_covariances_are_named():
    rng = np.random.default_rng(5)
    model, P, W, D, C = _problem(rng, poses=2, loads=6, repeats=1)
    C[3, 0, 5] = C[3, 5, 0] = 2.0 * SD[0] * SD[5]  # correlation 2: not positive definite
    with pytest.raises(InputError, match=r"cov: row 3 is not positive definite"):
        fit_deflections6(model, P, W, D, params=NAMES, cov=C)
    with pytest.raises(ValueError, match="not both"):
        fit_deflections6(model, P, W, D, params=NAMES, cov=C, std=np.ones((len(D), 6)))
    with pytest.raises(ValueError, match="extra_noise=True needs"):
        fit_deflections6(model, P, W, D, params=NAMES, extra_noise=True)


def test_the_shipped_hexapods_legs_with_extra_noise():
    # The real legs model (LegRobot6): legs recovered within 4 reported standard errors.
    hexapod = LegRobot.from_toml(files("stiffmap.models") / "robots" / "hexapod.toml")
    names = hexapod.param_names()
    k = np.array([hexapod.params()[n] for n in names])
    rng = np.random.default_rng(6)
    P = np.array([[x, y, 300.0, 0.0, 0.0, 0.0] for x in (-40.0, 40.0) for y in (-40.0, 40.0)])
    F = 200.0 * rng.normal(size=(9, 3))
    W = np.concatenate([F, np.cross(rng.normal(0.0, 100.0, (9, 3)), F)], axis=1)
    Pm, Wm = np.repeat(P, 18, axis=0), np.tile(W, (8, 1))
    D = np.linalg.solve(hexapod.evaluate(Pm).K6, Wm[..., None])[..., 0]
    S = _stated_covariance() * 0.01  # 0.2 um, 2 urad
    C = np.broadcast_to(S, (len(D), 6, 6)).copy()
    Dn = _noisy(rng, D, C, 4.0 * S)
    f = fit_deflections6(hexapod, Pm, Wm, Dn, params=names, cov=C, extra_noise=True)
    assert np.all(np.abs(f.estimate - k) < 4 * f.std), (f.estimate, k, f.std)
    assert np.all(np.abs(f.estimate - k) < 0.01 * k)
