"""Joint stiffnesses identified from measured deflections, on a PUMA-like arm built here.

The arm is the PUMA 560 in standard Denavit-Hartenberg form (Corke, "A robotics toolbox
for MATLAB", 1996, and his Robotics Toolbox model ``mdl_puma560``: a2 = 431.8 mm,
a3 = 20.32 mm, d3 = 150.05 mm, d4 = 431.8 mm, twists 90, 0, -90, 90, -90, 0 degrees),
its flange 56.25 mm beyond the wrist centre and a 100 mm tool. Its Jacobian is written
from the joint axes and checked against central differences of its forward kinematics,
which also fixes the convention: rows (v in mm/rad, omega in rad/rad) of the tool point in
the base frame, omega the rotation vector of R(q + dq) R(q)^T per dq.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from helpers.finite_difference import central_jacobian
from hypothesis import given
from hypothesis import strategies as st
from scipy.linalg import block_diag
from scipy.spatial.transform import Rotation

from stiffmap.errors import DesignError, IllConditionedWarning, InputError
from stiffmap.geometry import rotvec_from_matrix
from stiffmap.models import JointFit, fit_joint_compliances, joint_deflections, joint_identifiability

DH_A = np.array([0.0, 431.8, 20.32, 0.0, 0.0, 0.0])  # mm
DH_D = np.array([0.0, 0.0, 150.05, 431.8, 0.0, 0.0])  # mm
DH_ALPHA = np.array([np.pi / 2, 0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0.0])
FLANGE_MM = 56.25
TOOL_MM = FLANGE_MM + 100.0  # the tool point on the flange axis (joint 6)

# Joint stiffnesses of the order of a PUMA-size arm's (20 ... 2 kN*m/rad), N*mm/rad.
K_TRUE = np.array([2.0e7, 1.5e7, 1.0e7, 4.0e6, 3.0e6, 2.0e6])
C_TRUE = 1.0 / K_TRUE  # rad/(N*mm)
LOAD_N = 50.0
SIGMA = np.array([1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5])  # 1 um, 10 urad


def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st_, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [[ct, -st_ * ca, st_ * sa, a * ct], [st_, ct * ca, -ct * sa, a * st_], [0, sa, ca, d], [0, 0, 0, 1.0]]
    )


def _frames(q, tool_mm: float = TOOL_MM) -> tuple[list[np.ndarray], np.ndarray]:
    """Frames 0..6 (joint i turns about z of frame i-1) and the tool point's frame."""
    T = np.eye(4)
    out = [T]
    for i in range(6):
        T = T @ _dh(q[i], DH_D[i], DH_A[i], DH_ALPHA[i])
        out.append(T)
    tool = np.eye(4)
    tool[2, 3] = tool_mm
    return out, T @ tool


def _jacobian(q, tool_mm: float = TOOL_MM) -> tuple[np.ndarray, np.ndarray]:
    """Columns (z x (p - o), z) of the tool point, base frame; and the tool's pose (4 x 4)."""
    fr, tool = _frames(q, tool_mm)
    p = tool[:3, 3]
    J = np.zeros((6, 6))
    for i in range(6):
        z, o = fr[i][:3, 2], fr[i][:3, 3]
        J[:3, i] = np.cross(z, p - o)
        J[3:, i] = z
    return J, tool


def _wrist_for(q123, R_tool) -> np.ndarray:
    """Joints 4-6 that give the tool the orientation R_tool: R_36 = Rz(q4) Ry(-q5) Rz(q6)."""
    fr, _ = _frames(np.r_[q123, 0.0, 0.0, 0.0])
    a, b, c = Rotation.from_matrix(fr[3][:3, :3].T @ R_tool).as_euler("ZYZ")
    return np.r_[q123, a, -b, c]


def _configurations(n: int, seed: int) -> np.ndarray:
    """n configurations over the workspace, the wrist bent (|q5| >= 0.4 rad), elbow bent."""
    rng = np.random.default_rng(seed)
    q = rng.uniform([-2.5, -2.0, -0.6, -2.5, 0.4, -2.5], [2.5, -0.6, 1.2, 2.5, 1.8, 2.5], (n, 6))
    q[:, 4] *= rng.choice([-1.0, 1.0], n)
    return q


# The nine load cases: 50 N forces (base frame) at load points on a bracket 100 mm off the
# tool point, along the tool's x, y and z axes. Offset forces rather than pure moments,
# because that is how a lab loads an arm (masses and cable pulls on a bracket); the three
# offsets make moments about all three tool axes, so the wrist joints are felt in every
# configuration.
_X, _Y, _Z = np.eye(3)
LOAD_CASES = (
    ("A+x", _X, +_X),
    ("A-x", _X, -_X),
    ("A+y", _X, +_Y),
    ("A-y", _X, -_Y),
    ("A-z", _X, -_Z),
    ("B-z", _Y, -_Z),
    ("B+x", _Y, +_X),
    ("C+x", _Z, +_X),
    ("C+y", _Z, +_Y),
)


def _design(qs, load_cases=LOAD_CASES, offset_mm: float = 100.0, tool_mm: float = TOOL_MM):
    """Rows (configuration x load case): Jacobians (M, 6, 6), wrenches (M, 6), labels, configs."""
    Js, Ws, labels, cfg = [], [], [], []
    for k, q in enumerate(qs):
        J, tool = _jacobian(q, tool_mm)
        R = tool[:3, :3]
        for label, axis, direction in load_cases:
            r = offset_mm * (R @ axis)  # tool point -> load point, base frame
            F = LOAD_N * direction
            Js.append(J)
            Ws.append(np.r_[F, np.cross(r, F)])
            labels.append(label)
            cfg.append(k)
    return np.array(Js), np.array(Ws), labels, np.array(cfg)


def _covariances(M: int, seed: int = 11) -> np.ndarray:
    """A correlated 6x6 covariance per row (translations and rotations correlated, as a
    camera's pose is), scaled per row by 0.5 ... 2."""
    rng = np.random.default_rng(seed)
    B = np.eye(6) + 0.5 * rng.standard_normal((6, 6))
    S = B @ B.T
    rho = S / np.sqrt(np.outer(np.diag(S), np.diag(S)))
    base = rho * np.outer(SIGMA, SIGMA)
    scale = rng.uniform(0.5, 2.0, M)
    return base[None] * scale[:, None, None] ** 2


def _noise(cov: np.ndarray, seed: int) -> np.ndarray:
    L = np.linalg.cholesky(cov)
    z = np.random.default_rng(seed).standard_normal(cov.shape[:2])
    return np.einsum("mab,mb->ma", L, z)


@pytest.fixture(scope="module")
def arm():
    J, W, labels, cfg = _design(_configurations(20, seed=3))
    cov = _covariances(J.shape[0])
    return J, W, labels, cfg, cov, joint_deflections(J, W, C_TRUE)


def test_jacobian_matches_central_differences_of_the_forward_kinematics():
    """The test's analytic Jacobian and the convention: v = d p / d q (mm/rad), omega the
    rotation vector of R(q + dq) R(q)^T per dq (rad/rad), both in the base frame."""
    for q in _configurations(5, seed=1):
        J, tool = _jacobian(q)
        R0 = tool[:3, :3]
        Jv = central_jacobian(lambda x: _frames(x)[1][:3, 3], q, 1e-5)
        Jw = central_jacobian(lambda x, R0=R0: rotvec_from_matrix(_frames(x)[1][:3, :3] @ R0.T), q, 1e-5)
        # Truncation h^2 |p'''| / 6 and rounding eps |p| / h are both ~1e-8 mm here.
        assert np.max(np.abs(np.vstack([Jv, Jw]) - J)) <= 1e-6 * np.max(np.abs(J))


def test_the_forward_model_is_the_arm_deflected_by_its_joint_springs():
    """J C J^T w against the forward kinematics at q + C J^T w: the tool point's displacement
    and the rotation vector of R' R^T, to first order in the joint deflection (~1e-5 rad)."""
    q = _configurations(1, seed=2)[0]
    J, tool = _jacobian(q)
    w = np.array([30.0, -20.0, 40.0, 2000.0, -1500.0, 800.0])  # N, N*mm
    c = C_TRUE / 400  # small deflections: second-order terms ~1e-5 of the first
    dq = c * (J.T @ w)
    assert 1e-7 < np.max(np.abs(dq)) < 1e-5
    _, moved = _frames(q + dq)
    exact = np.r_[moved[:3, 3] - tool[:3, 3], rotvec_from_matrix(moved[:3, :3] @ tool[:3, :3].T)]
    model = joint_deflections(J[None], w[None], c)[0]
    assert np.max(np.abs(model - exact)) <= 1e-4 * np.max(np.abs(exact))
    # One wrench for all rows broadcasts; compliances per row too.
    two = joint_deflections(np.stack([J, J]), w, np.stack([c, 2 * c]))
    assert two[1] == pytest.approx(2 * model, rel=1e-12)


def test_recovers_the_joint_stiffnesses_with_standard_errors_that_match_the_scatter(arm):
    """20 configurations x 9 load cases, 6-DOF displacements with correlated noise (1 um,
    10 urad), 50 seeds: every estimate within 4 sigma, the reported standard errors equal the
    scatter over seeds (a sample std of 50 is itself uncertain by 10 %)."""
    J, W, labels, cfg, cov, clean = arm
    est, se = [], []
    for seed in range(50):
        f = fit_joint_compliances(J, W, clean + _noise(cov, seed), cov, labels=labels)
        est.append(f.compliance)
        se.append(f.compliance_std)
    est, se = np.array(est), np.array(se)
    z = (est - C_TRUE) / se
    assert np.all(np.abs(z) < 4)
    assert np.mean(np.abs(z) < 3) >= 0.98
    ratio = np.std(est, ddof=1, axis=0) / np.mean(se, axis=0)
    assert np.all((ratio > 0.75) & (ratio < 1.33)), ratio
    assert np.all(np.abs(f.stiffness / K_TRUE - 1) < 0.02)
    assert f.stiffness_std == pytest.approx(f.compliance_std / f.compliance**2, rel=1e-12)
    # The last fit's report: right model, right uncertainties.
    assert isinstance(f, JointFit) and f.fitted == f.names == ("k1", "k2", "k3", "k4", "k5", "k6")
    assert f.dof == 180 * 6 - 6 and f.p_value > 1e-3 and not f.notes and f.active == ()
    assert f.joint_types == ("revolute",) * 6
    assert f.condition < 100 and np.all(f.sensitivity > 1e-2)
    assert f.residual_rms_per_config.shape == (20, 2) and np.all(f.configs == np.arange(20))
    assert np.all((f.normalized_rms_per_config > 0.6) & (f.normalized_rms_per_config < 1.4))
    assert f.label_names == tuple(lc[0] for lc in LOAD_CASES)
    assert np.all((f.normalized_rms_per_label > 0.7) & (f.normalized_rms_per_label < 1.3))
    # Translation residuals of a few um, rotation residuals of ~10 urad.
    assert np.all(f.residual_rms_per_config[:, 0] < 5e-3) and np.all(f.residual_rms_per_config[:, 1] < 5e-5)


def test_noise_free_data_are_recovered_exactly(arm):
    J, W, labels, cfg, cov, clean = arm
    f = fit_joint_compliances(J, W, clean, cov, config_index=cfg)
    assert f.compliance == pytest.approx(C_TRUE, rel=1e-9)
    assert f.chi2 < 1e-12 and np.all(f.compliance_std < 1e-9 * C_TRUE)
    assert f.predict(J, W) == pytest.approx(clean, rel=1e-9, abs=1e-15)
    # Points only (translations, d = 3): joint 6 turns about the tool axis, through the
    # measured point, so it moves nothing measured whatever the loads; held at its value, the
    # offset loads determine the five others.
    with pytest.raises(DesignError, match="k6 is not felt: it moves nothing that is measured"):
        fit_joint_compliances(J, W, clean[:, :3], cov[:, :3, :3])
    f3 = fit_joint_compliances(J, W, clean[:, :3], cov[:, :3, :3], fixed={"k6": C_TRUE[5]})
    assert f3.compliance == pytest.approx(C_TRUE, rel=1e-9) and f3.residuals.shape == (180, 3)
    assert np.all(np.isnan(f3.residual_rms_per_config[:, 1]))
    # Holding joints at their true compliances and fitting the others gives the same.
    fixed = {"k1": C_TRUE[0], "k6": C_TRUE[5]}
    f4 = fit_joint_compliances(J, W, clean, cov, fixed=fixed)
    assert f4.fitted == ("k2", "k3", "k4", "k5") and f4.compliance == pytest.approx(C_TRUE, rel=1e-9)
    assert np.isnan(f4.compliance_std[[0, 5]]).all() and f4.covariance.shape == (4, 4)


def test_forces_through_the_tool_axis_leave_joint_6_unfelt_and_it_is_named():
    """Forces at the tool point (on joint 6's axis), translations only, one tool orientation:
    joint 6 sees no moment and moves the point by nothing. Joints 4 and 5 still are
    determined (their axes move with the arm), so the refusal names k6 alone."""
    R_down = Rotation.from_euler("x", np.pi).as_matrix()
    qs = [_wrist_for(q[:3], R_down) for q in _configurations(20, seed=4)]
    J, W, _, _ = _design(qs, LOAD_CASES[:5], offset_mm=0.0)
    D = joint_deflections(J, W, C_TRUE)[:, :3]
    with pytest.raises(DesignError) as exc:
        fit_joint_compliances(J, W, D, np.full((J.shape[0], 3), 1e-3))
    msg = str(exc.value)
    assert msg.startswith(
        "joint k6 cannot be determined from these configurations and loads: k6 is not felt: no load has a "
        "moment about its axis and it moves nothing that is measured (the measured point lies on its axis)"
    )
    assert "load cases with moments about the axis of k6 (a load point off its axis)" in msg
    assert not any(f"k{j}" in msg for j in range(1, 6))
    rep = joint_identifiability(J, W, measured=3)
    assert rep.undetermined == ("k6",) and rep.sensitivity[5] < 1e-12 and np.all(rep.sensitivity[:5] > 1e-2)
    assert np.all(np.isfinite(rep.inflation[:5])) and rep.inflation[5] == np.inf
    # Fitting only the determined joints (joint 6 held) works.
    f = fit_joint_compliances(J, W, D, np.full((J.shape[0], 3), 1e-3), fixed={"k6": 0.0})
    assert f.compliance[:5] == pytest.approx(C_TRUE[:5], rel=1e-9) and f.stiffness[5] == np.inf


def test_measuring_at_the_wrist_centre_leaves_the_wrist_unfelt():
    """The measured and loaded point at the wrist centre (no flange, no tool), forces only,
    translations only: the three wrist axes pass through it. Joints 1-3 are determined."""
    J, W, _, _ = _design(_configurations(20, seed=5), LOAD_CASES[:5], offset_mm=0.0, tool_mm=0.0)
    with pytest.raises(DesignError) as exc:
        fit_joint_compliances(J, W, joint_deflections(J, W, C_TRUE)[:, :3])
    msg = str(exc.value)
    assert msg.startswith(
        "joints k4, k5, k6 cannot be determined from these configurations and loads: k4, k5, k6 are not "
        "felt: no load has a moment about their axes and they move nothing that is measured"
    )
    assert "measure rotations (6-DOF poses) or a point off their axes (k4, k5, k6)" in msg
    assert not any(f"k{j}" in msg for j in range(1, 4))


def test_a_straight_wrist_confounds_joints_4_and_6_and_a_nearly_straight_one_warns(arm):
    """q5 = 0: the axes of joints 4 and 6 coincide, their columns are equal, the data see only
    c4 + c6. q5 = 1e-4 rad: determined, but the condition number (~1/q5) is warned about."""
    qs = _configurations(20, seed=6)
    qs[:, 4] = 0.0
    J, W, _, _ = _design(qs)
    cov = _covariances(J.shape[0])
    with pytest.raises(DesignError) as exc:
        fit_joint_compliances(J, W, joint_deflections(J, W, C_TRUE), cov)
    msg = str(exc.value)
    assert msg.startswith(
        "joints k4, k6 cannot be determined from these configurations and loads: k4, k6 change the "
        "measured displacements only in a fixed combination"
    )
    assert "add configurations where their axes lie differently" in msg
    assert not any(f"k{j}" in msg for j in (1, 2, 3, 5))
    rep = joint_identifiability(J, W, cov)
    assert rep.confounded == (("k4", "k6"),) and not rep.not_felt and rep.condition == np.inf
    assert np.abs(rep.directions[-1]) == pytest.approx([0, 0, 0, 2**-0.5, 0, 2**-0.5], abs=1e-6)
    qs[:, 4] = 1e-4
    J, W, _, _ = _design(qs)
    with pytest.warns(
        IllConditionedWarning, match=r"condition number \d.*e\+03 > 1000.*: 0.71 k4 - 0.71 k6\)$"
    ):
        f = fit_joint_compliances(J, W, joint_deflections(J, W, C_TRUE), cov)
    assert 1e3 < f.condition < 1e5
    assert f.identifiability.inflation[3] > 1e3 and f.identifiability.inflation[1] < 3


def test_joints_the_data_cannot_separate_are_named_below_the_condition_warning():
    """q5 = 0.003 rad: the axes of joints 4 and 6 nearly coincide, the data see almost
    only c4 + c6 (correlation -0.99997), yet the condition number is 254, below the 1e3 warning.
    With 100 um / 1 mrad of noise both standard errors exceed their values: one note names the
    pair, and no other joint. The well-posed design (the recovery test above, 50 seeds) has no
    notes at all."""
    qs = _configurations(20, seed=6)
    qs[:, 4] = 0.003
    J, W, labels, _ = _design(qs)
    cov = _covariances(J.shape[0]) * 100.0**2
    with warnings.catch_warnings():
        warnings.simplefilter("error", IllConditionedWarning)  # not the condition number's warning
        f = fit_joint_compliances(J, W, joint_deflections(J, W, C_TRUE) + _noise(cov, 1), cov, labels=labels)
    assert f.condition < 1e3 and f.correlation[3, 5] < -0.9999
    rel = f.stiffness_std / f.stiffness
    assert rel[3] > 1 and rel[5] > 1 and np.all(rel[[0, 1, 2, 4]] < 0.01)  # the case, computed here
    assert len(f.notes) == 1, f.notes
    assert f.notes[0].startswith("the data cannot separate k4 from k6 (correlation -1.0000): k4 = ")
    assert not any(f"k{j}" in f.notes[0] for j in (1, 2, 3, 5))


def test_a_rigid_joint_is_held_at_zero_and_said(arm):
    """Joint 3 rigid (c3 = 0): with noise its unconstrained estimate is negative about half the
    time; the bound holds it at 0, says so, and the others are those of a fit with k3 held
    at 0 (the constrained optimum)."""
    J, W, labels, cfg, cov, _ = arm
    c = C_TRUE.copy()
    c[2] = 0.0
    clean = joint_deflections(J, W, c)
    for seed in range(20):
        D = clean + _noise(cov, 100 + seed)
        if fit_joint_compliances(J, W, D, cov, nonnegative=False).compliance[2] < 0:
            break
    else:
        raise AssertionError("no seed gave a negative estimate")
    f = fit_joint_compliances(J, W, D, cov)
    assert f.active == ("k3",) and f.compliance[2] == 0.0 and f.stiffness[2] == np.inf
    assert np.isnan(f.compliance_std[2]) and np.isnan(f.stiffness_std[2])
    assert np.all(np.isnan(f.covariance[2])) and np.all(np.isnan(f.covariance[:, 2]))
    (note,) = f.notes
    assert note.startswith("compliance of k3 held at 0 (the unconstrained estimate was -")
    assert " rad/(N*mm) ± " in note and "the data favour a rigid joint" in note
    held = fit_joint_compliances(J, W, D, cov, fixed={"k3": 0.0})
    others = [0, 1, 3, 4, 5]
    assert f.compliance[others] == pytest.approx(held.compliance[others], rel=1e-9)
    assert f.compliance_std[others] == pytest.approx(held.compliance_std[others], rel=1e-9)
    assert f.chi2 == pytest.approx(held.chi2, rel=1e-9) and f.dof == held.dof
    d = json.loads(json.dumps(f.to_dict(), allow_nan=False))
    assert d["joints"]["k3"]["stiffness"] is None and d["joints"]["k3"]["active"] is True
    assert d["joints"]["k1"]["stiffness_unit"] == "N*mm/rad" and len(d["configs"]) == 20


def test_underestimated_noise_fails_the_chi_square_test_and_absolute_sigma_keeps_the_errors(arm):
    J, W, labels, cfg, cov, clean = arm
    D = clean + 3 * _noise(cov, 7)  # three times the noise the covariances say
    f = fit_joint_compliances(J, W, D, cov)
    assert 8 < f.reduced_chi2 < 10 and f.p_value < 1e-10
    (note,) = f.notes
    assert "does not explain the measurements (chi2/dof = " in note and "underestimated" in note
    fa = fit_joint_compliances(J, W, D, cov, absolute_sigma=True)
    assert fa.compliance == pytest.approx(f.compliance, rel=1e-12)
    assert f.compliance_std == pytest.approx(fa.compliance_std * np.sqrt(f.reduced_chi2), rel=1e-10)
    # Without covariances: unit weights, the standard errors from the scatter, no p-value.
    fu = fit_joint_compliances(J, W, D)
    assert np.isnan(fu.p_value) and np.all(np.abs(fu.compliance / C_TRUE - 1) < 0.05)


def test_a_cartesian_gantry_has_prismatic_joints_in_mm_per_n():
    """Three prismatic joints along x, y, z: J = [I; 0] everywhere, so u = diag(c) F. Forces
    along x and y only leave the z joint unloaded, which is said in those words."""
    J = np.tile(np.vstack([np.eye(3), np.zeros((3, 3))]), (4, 1, 1))
    W = np.array(
        [[100.0, 0, 0, 0, 0, 0], [0, 100.0, 0, 0, 0, 0], [0, 0, -100.0, 0, 0, 0], [50.0, 50.0, 0, 0, 0, 0]]
    )
    k = np.array([2000.0, 1500.0, 5000.0])  # N/mm
    D = joint_deflections(J, W, 1 / k)[:, :3]
    f = fit_joint_compliances(J, W, D, np.full((4, 3), 1e-3), joint_names=["x", "y", "z"])
    assert f.joint_types == ("prismatic",) * 3 and f.stiffness == pytest.approx(k, rel=1e-9)
    assert f.to_dict()["joints"]["z"]["stiffness_unit"] == "N/mm"
    with pytest.raises(
        DesignError, match=r"^joint z cannot be determined .*: z is not felt: no load has a force along"
    ):
        fit_joint_compliances(J[[0, 1, 3]], W[[0, 1, 3]], D[[0, 1, 3]], joint_names=["x", "y", "z"])


def _small():
    J, W, labels, cfg = _design(_configurations(3, seed=8))
    D = joint_deflections(J, W, C_TRUE)
    return dict(jacobians=J, wrenches=W, displacements=D, cov=_covariances(J.shape[0]))


def _with(**changes):
    args = _small()
    for k, v in changes.items():
        args[k] = v(args[k]) if callable(v) else v
    return args


def _set(a, index, value):
    a = np.array(a, dtype=float)
    a[index] = value
    return a


NAMES = "k1, k2, k3, k4, k5, k6"


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (_with(jacobians=lambda J: J[:, :5]), r"^jacobians: expected shape \(M, 6, n\)"),
        (_with(jacobians=lambda J: _set(J, (2, 0, 0), np.nan)), r"^jacobians: row 2 contains NaN"),
        (_with(wrenches=lambda W: W[:, :3]), r"^wrenches: expected shape \(27, 6\)"),
        (_with(wrenches=lambda W: _set(W, (5, 4), np.inf)), r"^wrenches: row 5 contains NaN or infinite"),
        (_with(displacements=lambda D: D[:, :4]), r"^displacements: expected shape \(27, 3\)"),
        (_with(displacements=lambda D: _set(D, (7, 1), np.nan)), r"^displacements: row 7 contains NaN"),
        (_with(cov=lambda C: C[:, :3, :3]), r"^cov: expected shape \(27, 6, 6\)"),
        (_with(cov=lambda C: _set(C, (4, 0, 0), -1e-6)), r"^cov: row 4 is not positive definite"),
        (_with(cov=lambda C: _set(C, (1, 0, 1), 1e-7)), r"^cov: row 1 is not symmetric"),
        (
            _with(cov=lambda C: _set(np.sqrt(np.diagonal(C, axis1=1, axis2=2)), (3, 2), 0.0)),
            r"^cov: row 3 has",
        ),
        (_with(fit=["k1", "k7"]), rf"^fit: unknown joint\(s\) k7; joints: {NAMES}$"),
        (_with(fit=["k1", "k1"]), r"^fit: k1 given more than once"),
        (_with(fixed={"k9": 1e-7}), rf"^fixed: unknown joint\(s\) k9; joints: {NAMES}$"),
        (_with(fixed={"k6": -1e-7}), r"^fixed: k6 must be a finite non-negative compliance"),
        (
            _with(fit=["k1", "k2", "k3", "k4", "k5"]),
            r"^fixed: no compliance for k6, neither fitted nor fixed",
        ),
        (_with(fit=["k5", "k6"], fixed={"k6": 1e-7}), r"^fit: k6 also held in fixed"),
        (_with(joint_names=["a", "b"]), r"^joint_names: expected 6 names"),
        (_with(cov=None, absolute_sigma=True), r"^absolute_sigma: True needs cov"),
        (_with(labels=["x"] * 5), r"^labels: expected 27 load-case labels"),
        (_with(config_index=np.zeros(27)), r"^config_index: expected 27 integers"),
    ],
)
def test_bad_input_names_the_argument_and_the_row(args, match):
    with pytest.raises(InputError, match=match) as exc:
        fit_joint_compliances(**args)
    assert not isinstance(exc.value, DesignError)


def test_fewer_observations_than_joints_and_bad_forward_model_input_are_refused():
    args = _small()
    one = {k: v[:1, ..., :3, :3] if k == "cov" else v[:1] for k, v in args.items()}
    one["displacements"] = one["displacements"][:, :3]
    with pytest.raises(
        DesignError, match=r"^3 observation\(s\) \(1 row\(s\) of 3 components\) cannot determine 6"
    ):
        fit_joint_compliances(**one)
    rep = joint_identifiability(one["jacobians"], one["wrenches"], measured=3)
    assert rep.message.startswith("3 observation(s)") and rep.undetermined == rep.names
    with pytest.raises(InputError, match=r"^compliances: expected shape \(6,\) or \(27, 6\), got \(5,\)"):
        joint_deflections(args["jacobians"], args["wrenches"], C_TRUE[:5])


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), rows=st.integers(2, 6))
def test_the_estimate_is_generalised_least_squares_and_invariant_to_the_base_frame(seed, n, rows):
    """Random full designs with full random covariances: the estimate is the textbook GLS
    (A^T S^-1 A)^-1 A^T S^-1 y with the block-diagonal S (a fit that used only the diagonal
    of each covariance would fail), and rotating the base frame (Jacobians, wrenches,
    displacements and covariances alike) and permuting the rows changes nothing."""
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((rows, 6, n)) * np.r_[[100.0] * 3, [1.0] * 3][None, :, None]
    W = rng.standard_normal((rows, 6)) * np.r_[[50.0] * 3, [5000.0] * 3]
    c = rng.uniform(0.5, 2.0, n) * 1e-7
    B = rng.standard_normal((rows, 6, 6)) * np.r_[[1e-3] * 3, [1e-5] * 3][None, :, None]
    cov = B @ np.swapaxes(B, 1, 2) + np.diag(np.r_[[1e-8] * 3, [1e-12] * 3])
    D = joint_deflections(J, W, c) + np.einsum(
        "mab,mb->ma", np.linalg.cholesky(cov), rng.standard_normal((rows, 6))
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IllConditionedWarning)  # random designs may be poor
        f = fit_joint_compliances(J, W, D, cov, nonnegative=False)
        A = np.einsum("mkj,mj->mkj", J, np.einsum("mkj,mk->mj", J, W)).reshape(-1, n)
        Si = np.linalg.inv(block_diag(*cov))
        gls = np.linalg.solve(A.T @ Si @ A, A.T @ Si @ D.reshape(-1))
        assert f.compliance == pytest.approx(gls, rel=1e-6, abs=1e-6 * np.max(np.abs(gls)))
        R = Rotation.random(random_state=seed % 2**31).as_matrix()
        R6 = block_diag(R, R)
        perm = rng.permutation(rows)
        g = fit_joint_compliances(
            np.einsum("ab,mbj->maj", R6, J)[perm],
            (W @ R6.T)[perm],
            (D @ R6.T)[perm],
            (R6 @ cov @ R6.T)[perm],
            nonnegative=False,
        )
    scale = np.max(np.abs(f.compliance))
    assert g.compliance == pytest.approx(f.compliance, rel=1e-8, abs=1e-8 * scale)
    assert g.chi2 == pytest.approx(f.chi2, rel=1e-6, abs=1e-9)
    assert g.condition == pytest.approx(f.condition, rel=1e-6)
