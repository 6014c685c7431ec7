"""The model fits do not depend on their starting values (models.fit: the linear start).

A user does not know the stiffnesses before the fit: starts 1e-4 .. 1e4 off (all by one factor,
and by a random factor per parameter) must give the estimate of a start at the truth, to 1e-6
(relative), and that estimate must be the truth within the noise. The data are simulated from
the models themselves (known stiffnesses, small noise).
"""

from __future__ import annotations

import warnings
from importlib.resources import files

import numpy as np
import pytest

from stiffmap.errors import DesignError
from stiffmap.models import PRR3
from stiffmap.models.fit import (
    LinearView,
    fit_deflections6,
    fit_static_errors,
    fit_stiffness,
    linear_start,
    static_error_predictions,
)
from stiffmap.models.legs import LegRobot
from stiffmap.models.presets import prr3_points22
from stiffmap.models.serial import SerialRobot

ARM6 = str(files("stiffmap.models") / "robots" / "arm6.urdf")
HEXAPOD = files("stiffmap.models") / "robots" / "hexapod.toml"
K_ARM = np.array([2.0e9, 1.5e9, 1.0e9, 3.0e8, 2.5e8, 2.0e8])  # N*mm/rad
K_LEGS = np.array([450.0, 375.0, 550.0, 400.0, 525.0, 600.0])  # N/mm
JOINTS = [f"k{i}" for i in range(1, 7)]


def _starts(truth: np.ndarray, rng) -> list[np.ndarray]:
    """Starts 1e-4 and 1e4 off (every parameter), and 1e-4 .. 1e4 off at random per parameter."""
    return [truth * 1e-4, truth * 1e4, truth * 10 ** rng.uniform(-4, 4, truth.size)]


def _at(model, names, values):
    """The model with the named parameters at the values."""
    return model.with_params(**dict(zip(names, np.asarray(values).tolist(), strict=True)))


def _arm6(rng, m: int = 12) -> SerialRobot:
    """arm6 at m random configurations away from its singularities (the measured point off the
    wrist axes, so that every joint moves it)."""
    lo = np.radians([-150, -30, -60, -120, 25, -150])
    hi = np.radians([150, 60, 20, 120, 90, 150])
    Q = rng.uniform(lo, hi, size=(m, 6))
    Q[:, 4] *= rng.choice([-1.0, 1.0], m)
    return SerialRobot.from_urdf(ARM6, "tool0", (30.0, -20.0, 120.0), k_theta=K_ARM, configurations=Q)


def _same_from_every_start(fit, truth: np.ndarray, rng) -> np.ndarray:
    """The estimate from a start at the truth, after checking every other start gives it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        good = fit(truth)
        for start in _starts(truth, rng):
            est = fit(start).estimate
            np.testing.assert_allclose(est, good.estimate, rtol=1e-6, err_msg=f"start {start / truth}")
    return good


def test_arm6_joint_stiffnesses_from_static_errors_whatever_the_start(rng):
    robot = _arm6(rng)
    P = np.repeat(robot.evaluate_configurations(robot.configurations).points, 3, axis=0)
    F = 1000.0 * rng.normal(size=P.shape)
    U = rng.normal(size=P.shape)
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    exact = static_error_predictions(robot, P, F, U)
    std = 1e-3 * np.abs(exact).mean() * np.ones(exact.size)
    y = exact + std * rng.standard_normal(exact.size)

    def fit(k):
        return fit_static_errors(_at(robot, JOINTS, k), P, F, U, y, params=JOINTS, std=std)

    good = _same_from_every_start(fit, K_ARM, rng)
    assert np.all(np.abs(good.estimate - K_ARM) < 5 * good.std), (good.estimate / K_ARM, good.std / K_ARM)


def test_arm6_joint_stiffnesses_from_stiffness_matrices_whatever_the_start(rng):
    robot = _arm6(rng)
    P = robot.evaluate_configurations(robot.configurations).points
    K = robot.stiffness(P)
    Km = K * (1 + 1e-3 * rng.standard_normal(K.shape))

    def fit(k):
        return fit_stiffness(_at(robot, JOINTS, k), P, Km, params=JOINTS)

    good = _same_from_every_start(fit, K_ARM, rng)
    assert np.all(np.abs(good.estimate - K_ARM) < 5 * good.std), (good.estimate / K_ARM, good.std / K_ARM)


@pytest.fixture(scope="module")
def hexapod():
    robot = LegRobot.from_toml(HEXAPOD)
    return robot.with_params(**dict(zip(robot.param_names(), K_LEGS, strict=True)))


def _hexapod_poses(rng, m: int = 10) -> np.ndarray:
    xy, z, rpy = rng.uniform(-40, 40, (m, 2)), rng.uniform(280, 330, (m, 1)), rng.uniform(-0.1, 0.1, (m, 3))
    return np.hstack([xy, z, rpy])


def test_hexapod_legs_from_6dof_deflections_whatever_the_start(hexapod, rng):
    P = _hexapod_poses(rng)
    W = np.hstack([20.0 * rng.normal(size=(len(P), 3)), 2000.0 * rng.normal(size=(len(P), 3))])
    D = np.linalg.solve(hexapod.stiffness6(P), W[..., None])[..., 0]
    D *= 1 + 1e-3 * rng.standard_normal(D.shape)
    names = hexapod.param_names()

    def fit(k):
        return fit_deflections6(_at(hexapod, names, k), P, W, D, params=names)

    good = _same_from_every_start(fit, K_LEGS, rng)
    assert np.all(np.abs(good.estimate - K_LEGS) < 5 * good.std), (good.estimate / K_LEGS, good.std / K_LEGS)


def test_hexapod_legs_from_K6_the_linear_start_is_the_answer(hexapod, rng):
    """K6 = sum k_i (leg lines): linear in the legs' stiffnesses, so the linear start is the
    least-squares solution itself (checked against numpy's lstsq on the K6 of each leg alone)."""
    P = _hexapod_poses(rng)
    Km = hexapod.stiffness6(P) * (1 + 1e-3 * rng.standard_normal((len(P), 6, 6)))
    names = hexapod.param_names()
    ones = dict.fromkeys(names, 1.0)
    K1 = hexapod.with_params(**ones).stiffness6(P)
    A = np.stack([(hexapod.with_params(**{**ones, n: 2.0}).stiffness6(P) - K1).reshape(-1) for n in names], 1)
    L = float(hexapod.length_mm)
    w = np.broadcast_to(np.outer(*2 * [np.array([1.0, 1.0, 1.0, L, L, L])]), Km.shape).reshape(-1)
    k_lstsq = np.linalg.lstsq(A / w[:, None], Km.reshape(-1) / w, rcond=None)[0]

    def weigh(r):
        return r / w

    def predict(m):
        return m.stiffness6(P).reshape(-1)

    x, exact = linear_start(hexapod, names, K_LEGS * 1e3, [LinearView(predict, Km.reshape(-1))], weigh)
    np.testing.assert_allclose(np.exp(x), k_lstsq, rtol=1e-8)
    assert exact  # the fit's own minimum: the fit starts there, whatever the start
    f = fit_stiffness(_at(hexapod, names, K_LEGS * 1e-4), P, Km, params=names)
    np.testing.assert_allclose(f.estimate, k_lstsq, rtol=1e-8)


def test_a_model_not_linear_in_its_springs_still_converges_from_far(rng):
    """The 3PRR's kj and kb (each leg an actuator and a bar) are linear neither in the
    stiffnesses nor in the compliances: the linearised start takes it from 1e3 off."""
    P = prr3_points22()
    pts = np.vstack([P, P])
    F = np.vstack([np.tile([490.5, 0.0], (22, 1)), np.tile([0.0, 490.5], (22, 1))])
    U = F / 490.5
    truth = PRR3()
    y = static_error_predictions(truth, pts, F, U) * (1 + 1e-3 * rng.standard_normal(44))
    names = ("kj", "kb")

    def fit(k):
        return fit_static_errors(_at(truth, names, k), pts, F, U, y, params=names)

    k_true = np.array([truth.kj, truth.kb])
    own = LinearView(lambda m: static_error_predictions(m, pts, F, U), y)
    assert linear_start(truth, names, k_true, [own], lambda r: r) is None
    _same_from_every_start(fit, k_true, rng)


def test_a_joint_the_data_cannot_feel_is_still_refused_by_name(rng):
    """The measured point on joint 6's axis, forces only: k6 moves nothing, from any start."""
    robot = _arm6(rng)
    robot = SerialRobot.from_urdf(ARM6, "tool0", k_theta=K_ARM, configurations=robot.configurations)
    P = robot.evaluate_configurations(robot.configurations).points
    K = robot.stiffness(P)
    for start in [K_ARM, *_starts(K_ARM, rng)]:
        with pytest.raises(DesignError, match=r"the data cannot determine k6"):
            fit_stiffness(_at(robot, JOINTS, start), P, K, params=JOINTS)
