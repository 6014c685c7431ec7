"""Fitting model parameters to simulated measurements: recovery, standard errors, refusals."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers.finite_difference import central_jacobian

from stiffmap.errors import DesignError
from stiffmap.models import PRR3, DeltaRobot, IKSolution, Mechanism, PoseError
from stiffmap.models.base import model_map
from stiffmap.models.fit import ModelFit, fit_static_errors, fit_stiffness, static_error_predictions
from stiffmap.models.presets import paper48, prr3_points22

LOAD_N = 490.5  # the milling study's 50 kgf


def _sensor_design():
    """The milling study's protocol at the 22 points: a horizontal and a vertical 50 kgf load,
    the displacement read along the load (one component per recording)."""
    P = prr3_points22()
    pts = np.vstack([P, P])
    F = np.vstack([np.tile([LOAD_N, 0.0], (22, 1)), np.tile([0.0, LOAD_N], (22, 1))])
    return pts, F, F / LOAD_N


def _simulate_static(model, rng, rel_noise=0.02):
    pts, F, U = _sensor_design()
    true = static_error_predictions(model, pts, F, U)
    std = rel_noise * np.abs(true)
    return pts, F, U, true + std * rng.standard_normal(true.size), std


def test_fit_kj_recovers_it_within_1_percent_with_consistent_standard_error():
    truth = PRR3()  # kj = 525 N/mm, kb = 9800 N/mm (milling study)
    start = truth.with_params(kj=300.0)
    est, se = [], []
    for seed in range(40):
        pts, F, U, y, std = _simulate_static(truth, np.random.default_rng(seed))
        f = fit_static_errors(start, pts, F, U, y, params=("kj",), std=std)
        est.append(f.estimate[0])
        se.append(f.std[0])
        assert f.converged and f.dof == 43 and f.poses.shape == (22, 2)
    est, se = np.array(est), np.array(se)
    assert np.all(np.abs(est / 525.0 - 1) < 0.01)
    # The reported standard error agrees with the scatter of the estimates over seeds (the sample
    # standard deviation of 40 estimates is itself uncertain by ~11 %).
    assert np.std(est, ddof=1) == pytest.approx(np.mean(se), rel=0.3)
    assert np.mean(np.abs(est - 525.0) < 2 * se) >= 0.85
    assert np.mean(se) / 525.0 < 0.005
    assert not f.notes  # a right model fits within the errors: no misfit note


def test_fitting_with_a_wrong_fixed_parameter_is_called_a_misfit():
    """Data of a 3PRR with 265 mm rods, fitted (kj) with the default 250 mm: kj alone cannot fit."""
    truth = PRR3(L=265.0)
    pts, F, U, y, std = _simulate_static(truth, np.random.default_rng(1))
    f = fit_static_errors(PRR3(), pts, F, U, y, params=("kj",), std=std)
    assert f.reduced_chi2 > 5
    assert any("does not explain the measurements" in n and "p = " in n for n in f.notes)


def test_fit_k_theta_of_the_delta_from_noisy_matrices_at_the_reference_grid():
    truth = DeltaRobot()
    P = paper48()
    K = truth.stiffness(P)
    # 2 % noise: each entry of a pose's K scattered by 2 % of that K's RMS entry.
    sig = np.broadcast_to(0.02 * np.sqrt(np.mean(K**2, axis=(1, 2)))[:, None, None], K.shape)
    est, se = [], []
    for seed in range(40):
        Km = K + sig * np.random.default_rng(seed).standard_normal(K.shape)
        f = fit_stiffness(truth.with_params(k_theta=1.0e5), P, Km, params=("k_theta",), K_std=sig)
        est.append(f.estimate[0])
        se.append(f.std[0])
    est, se = np.array(est), np.array(se)
    assert np.all(np.abs(est / truth.k_theta - 1) < 0.01)
    assert np.std(est, ddof=1) == pytest.approx(np.mean(se), rel=0.3)
    assert np.mean(np.abs(est - truth.k_theta) < 2 * se) >= 0.85
    assert f.residuals.shape == (48 * 9,) and f.residual_rms_per_pose.shape == (48,)


def test_fit_kj_and_kb_together():
    truth = PRR3()
    pts, F, U, y, std = _simulate_static(truth, np.random.default_rng(7), rel_noise=0.005)
    f = fit_static_errors(truth.with_params(kj=400.0, kb=5000.0), pts, F, U, y, params=("kj", "kb"), std=std)
    assert f.names == ("kj", "kb")
    for name, true in (("kj", 525.0), ("kb", 9800.0)):
        assert abs(f.values[name] - true) < 4 * f.std_values[name]
    # kb is felt far less than kj: its relative standard error is much larger.
    assert f.std_values["kb"] / f.values["kb"] > 5 * f.std_values["kj"] / f.values["kj"]
    assert -1 < f.correlation[0, 1] < 1 and f.condition >= 1
    assert f.model.kj == f.values["kj"] and f.model.kb == f.values["kb"]


def test_noise_free_data_give_the_truth_exactly_and_absolute_sigma():
    truth = PRR3(kj=610.0)
    pts, F, U = _sensor_design()
    y = static_error_predictions(truth, pts, F, U)
    f = fit_static_errors(
        PRR3(), pts, F, U, y, params=("kj",), std=np.full(y.size, 0.01), absolute_sigma=True
    )
    assert f.values["kj"] == pytest.approx(610.0, rel=1e-8)
    np.testing.assert_allclose(f.residuals, 0.0, atol=1e-9)
    # absolute sigma: the standard error follows from the given 0.01 mm alone (linearised):
    # var(log kj) = 1 / sum((d y / d log kj / sigma)^2).
    dy = central_jacobian(
        lambda log_kj: static_error_predictions(truth.with_params(kj=610.0 * np.exp(log_kj)), pts, F, U),
        0.0,
        1e-6,
    )
    se = 610.0 / np.sqrt(np.sum((dy / 0.01) ** 2))
    assert f.std[0] == pytest.approx(se, rel=1e-4)


def test_model_fit_is_immutable():
    truth = PRR3()
    pts, F, U, y, std = _simulate_static(truth, np.random.default_rng(1))
    f = fit_static_errors(truth, pts, F, U, y, std=std)
    assert isinstance(f, ModelFit)
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.estimate = np.array([1.0])  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        f.estimate[0] = 1.0
    d = f.to_dict()
    assert d["parameters"]["kj"]["estimate"] == f.values["kj"] and len(d["poses"]) == 22


def test_parameters_entering_only_as_a_product_are_refused():
    truth = PRR3()
    pts, F, U, y, std = _simulate_static(truth, np.random.default_rng(2))
    with pytest.raises(DesignError, match=r"cannot tell area, E apart"):
        fit_static_errors(truth, pts, F, U, y, params=("area", "E"), std=std)


def test_an_insensitive_parameter_is_refused():
    # A rigid bearing (kb = 1e12 N/mm) leaves the static errors unchanged by kb.
    rigid = PRR3(kb=1e12)
    pts, F, U, y, std = _simulate_static(rigid, np.random.default_rng(3))
    with pytest.raises(DesignError, match=r"the data cannot determine kb: the predictions do not change"):
        fit_static_errors(rigid, pts, F, U, y, params=("kb",), std=std)


def test_bad_requests_are_refused_clearly():
    m = PRR3()
    pts, F, U, y, std = _simulate_static(m, np.random.default_rng(4))
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) to fit for 3prr: k_j; valid: h, L, area"):
        fit_static_errors(m, pts, F, U, y, params=("k_j",))
    with pytest.raises(ValueError, match="given more than once: kj"):
        fit_static_errors(m, pts, F, U, y, params=("kj", "kj"))
    with pytest.raises(DesignError, match=r"1 observation\(s\) cannot determine 2 parameters"):
        fit_static_errors(m, pts[:1], F[:1], U[:1], y[:1], params=("kj", "kb"))
    with pytest.raises(DesignError, match="every force is zero"):
        fit_static_errors(m, pts, 0 * F, U, y)
    with pytest.raises(ValueError, match=r"directions\[0\] = \[2.0, 0.0\] is not a unit vector"):
        fit_static_errors(m, pts, F, 2 * U, y)
    with pytest.raises(ValueError, match=r"std must be positive and finite; entry \(3,\) is 0.0"):
        fit_static_errors(m, pts, F, U, y, std=np.where(np.arange(y.size) == 3, 0.0, std))
    bad = pts.copy()
    bad[5] = [400.0, 900.0]
    with pytest.raises(PoseError, match=r"observation 5: pose \(400, 900\) mm unreachable"):
        fit_static_errors(m, bad, F, U, y)
    with pytest.raises(ValueError, match="kj must be a positive number"):
        m.with_params(kj=0.0)
    with pytest.raises(ValueError, match=r"K must have shape \(48, 3, 3\)"):
        fit_stiffness(DeltaRobot(), paper48(), np.zeros((48, 2, 2)))


@dataclasses.dataclass(frozen=True)
class _AxisSprings:
    """A user-defined mechanism (not part of stiffmap): a planar gantry whose tool is held by a
    spring kx along x and ky along y, reachable in the square [0, 100]^2 mm."""

    kx: float = 50.0
    ky: float = 80.0
    name = "gantry"
    dim = 2

    def params(self):
        return {"kx": self.kx, "ky": self.ky}

    def with_params(self, **p):
        return dataclasses.replace(self, **p)

    def inverse_kinematics(self, points):
        P = np.atleast_2d(np.asarray(points, dtype=float))
        ok = np.all((P >= 0) & (P <= 100), axis=1)
        return IKSolution(
            np.where(ok[:, None], P, np.nan), ok, tuple("" if o else "unreachable: off" for o in ok)
        )

    def evaluate(self, points):
        P = np.atleast_2d(np.asarray(points, dtype=float))
        ik = self.inverse_kinematics(P)
        K = np.broadcast_to(np.diag([self.kx, self.ky]), (P.shape[0], 2, 2))
        return model_map(self.name, self.params(), P, K, ik.reachable, ik.reasons, ik.q, np.ones(P.shape[0]))

    def stiffness(self, points):
        return self.evaluate(points).K

    def static_error(self, points, force):
        return self.evaluate(points).static_error(force)


def test_a_user_defined_mechanism_plugs_into_maps_and_fits():
    g = _AxisSprings()
    assert isinstance(g, Mechanism)
    m = g.evaluate([[10.0, 10.0], [200.0, 0.0]])
    np.testing.assert_array_equal(m.valid, [True, False])
    assert np.isnan(m.K[1]).all() and m.det[0] == pytest.approx(4000.0)
    rng = np.random.default_rng(11)
    P = rng.uniform(0, 100, size=(30, 2))
    F = rng.normal(scale=20.0, size=(30, 2))
    U = np.tile([[1.0, 0.0], [0.0, 1.0]], (15, 1))
    y = static_error_predictions(_AxisSprings(kx=42.0, ky=95.0), P, F, U)
    f = fit_static_errors(g, P, F, U, y, params=("kx", "ky"))
    np.testing.assert_allclose([f.values["kx"], f.values["ky"]], [42.0, 95.0], rtol=1e-8)
    assert f.model.name == "gantry"
