"""3PRR model: the milling study's kinematics (eqs. 1-3), the truss against anastruct, presets."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers.mechanism_checks import assert_jacobian_matches_fd, random_reachable_poses

from stiffmap.kinds import position_presets, preset_points
from stiffmap.models import PRR3, Mechanism, PoseError
from stiffmap.models.presets import PRR3_MIDDLE_LINE, paper48, prr3_points22
from stiffmap.models.prr3 import K_B_PUBLISHED, K_J_PUBLISHED

BOX_LO = (100.0, -50.0)
BOX_HI = (700.0, 500.0)


def test_prr3_is_a_mechanism_with_the_published_stiffnesses():
    m = PRR3()
    assert isinstance(m, Mechanism)
    assert (m.name, m.dim) == ("3prr", 2)
    # Milling study, Section 4: K_b = 9800 N/mm (catalogue), K_j = 525 N/mm (fitted).
    assert (m.kb, m.kj) == (K_B_PUBLISHED, K_J_PUBLISHED) == (9800.0, 525.0)
    assert set(m.params()) == {"h", "L", "area", "E", "kj", "kb"}


def test_ik_satisfies_the_papers_equations(rng):
    m = PRR3()
    T = random_reachable_poses(m, rng, 300, BOX_LO, BOX_HI, margin=0.0)
    x, y = T[:, 0], T[:, 1]
    l1, l2, l3 = m.inverse_kinematics(T).q.T
    h, L = m.h, m.L
    s3 = math.sqrt(3)
    # Eqs. (1)-(3) of the milling study, written as printed (mm^2).
    np.testing.assert_allclose((x - s3 / 2 * l1) ** 2 + (y - l1 / 2) ** 2, L**2, rtol=1e-12)
    np.testing.assert_allclose((x - h + s3 / 2 * l2) ** 2 + (y - l2 / 2) ** 2, L**2, rtol=1e-12)
    np.testing.assert_allclose((x - h / 2) ** 2 + (y - s3 / 2 * h + l3) ** 2, L**2, rtol=1e-12)
    q = m.inverse_kinematics(T).q
    assert np.all((q >= 0) & (q <= h / s3))
    np.testing.assert_allclose(m.forward_kinematics(q), T, atol=1e-8)
    np.testing.assert_allclose(m.forward_kinematics(q[0]), T[0], atol=1e-8)


def test_jacobian_matches_central_differences(rng):
    m = PRR3()
    T = random_reachable_poses(m, rng, 300, BOX_LO, BOX_HI)
    assert_jacobian_matches_fd(m, T, h=1e-3, atol=1e-6)


def _anastruct_tool_displacement(m: PRR3, T: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The same truss in anastruct: rods as truss elements (EA), each slider's springs as truss
    elements of axial stiffness kj (along the rail) and kb (across it) to hinged supports."""
    from anastruct import SystemElements  # lazy: it loads matplotlib, for this one test only

    lg = m.legs(T)
    u = lg.u
    uperp = np.stack([-u[:, 1], u[:, 0]], axis=1)
    ell = 100.0  # length of the spring bars, mm: EA = k * ell gives axial stiffness k
    ss = SystemElements()
    supports = []
    for i in range(3):
        S = lg.S[0, i]
        ss.add_truss_element([S.tolist(), T.tolist()], EA=m.E * m.area)
        for d, k in ((u[i], m.kj), (uperp[i], m.kb)):
            ss.add_truss_element([(S - ell * d).tolist(), S.tolist()], EA=k * ell)
            supports.append((S - ell * d).tolist())
    for A in supports:
        ss.add_support_hinged(ss.find_node_id(A))
    tool = ss.find_node_id(T.tolist())
    ss.point_load(tool, Fx=float(F[0]), Fy=float(F[1]))
    ss.solve()
    r = ss.get_node_displacements(tool)
    return np.array([r["ux"], r["uy"]], dtype=float)


def test_truss_equals_anastruct_on_random_poses_and_stiffnesses(rng):
    for _ in range(25):
        m = PRR3(
            kj=rng.uniform(100, 3000),
            kb=rng.uniform(2000, 50000),
            E=rng.uniform(20000, 210000),
            area=rng.uniform(20, 400),
        )
        T = random_reachable_poses(m, rng, 1, BOX_LO, BOX_HI)[0]
        F = rng.normal(scale=300.0, size=2)
        u_closed = m.static_error(T, F)
        d_full = m.truss_displacements(T, F)
        u_fe = _anastruct_tool_displacement(m, T, F)
        np.testing.assert_allclose(d_full[0], u_closed, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(u_fe, u_closed, rtol=0, atol=1e-6 * np.linalg.norm(u_closed))
        # Equilibrium of the full truss: each slider moves by Ks^-1 (rod force along n).
        lg = m.legs(T)
        for i in range(3):
            n = lg.n[0, i]
            f = m.E * m.area / m.L * n @ (d_full[0] - d_full[1 + i])
            ui, vi = lg.u[i], np.array([-lg.u[i, 1], lg.u[i, 0]])
            Ks = m.kj * np.outer(ui, ui) + m.kb * np.outer(vi, vi)
            np.testing.assert_allclose(Ks @ d_full[1 + i], f * n, atol=1e-9 * abs(f) + 1e-12)


def test_redundancy_removes_the_two_leg_singularity():
    # At T = (h/2, (h - 2L)/(2 sqrt 3)) rods 1 and 2 are horizontal and opposite (a 2PRR made of
    # legs 1 and 2 would be singular: no vertical stiffness) and rod 3 is vertical. By hand:
    # K = diag(2 / (3/(4 kj) + 1/(4 kb) + L/EA), 1 / (1/kj + L/EA)).
    m = PRR3()
    s3 = math.sqrt(3)
    lpos = (m.h - 2 * m.L) / s3
    T = np.array([m.h / 2, lpos / 2])
    lg = m.legs(T)
    np.testing.assert_allclose(lg.n[0, 0], [1, 0], atol=1e-12)
    np.testing.assert_allclose(lg.n[0, 1], [-1, 0], atol=1e-12)
    rod = m.L / (m.E * m.area)
    K = m.stiffness(T)
    expected = np.diag([2 / (0.75 / m.kj + 0.25 / m.kb + rod), 1 / (1 / m.kj + rod)])
    np.testing.assert_allclose(K, expected, rtol=1e-12, atol=1e-9)


def test_mirror_symmetry_about_the_middle_line(rng):
    # Rails 1 and 2 mirror each other about x = h/2 and rail 3 lies on it: the static error of the
    # mirrored pose under the mirrored force is the mirrored static error.
    m = PRR3()
    T = random_reachable_poses(m, rng, 50, BOX_LO, BOX_HI)
    F = rng.normal(scale=400.0, size=T.shape)
    flip = np.array([-1.0, 1.0])
    Tm = T * flip + [m.h, 0.0]
    np.testing.assert_allclose(
        m.static_error(Tm, F * flip), m.static_error(T, F) * flip, rtol=1e-9, atol=1e-12
    )


def test_stiffness_is_symmetric_positive_and_softer_with_softer_joints(rng):
    m = PRR3()
    T = random_reachable_poses(m, rng, 200, BOX_LO, BOX_HI)
    K = m.stiffness(T)
    np.testing.assert_array_equal(K, np.swapaxes(K, 1, 2))
    assert np.all(np.linalg.eigvalsh(K) > 0)
    Ks = m.with_params(kj=m.kj / 2).stiffness(T)
    assert np.all(np.linalg.eigvalsh(K - Ks) > -1e-9)


def test_points22_reconstruction():
    m = PRR3()
    P = prr3_points22()
    assert P.shape == (22, 2) and len({tuple(p) for p in P}) == 22
    # Points 2, 5, 8, 22, 15, 19, 20, 21 lie on the vertical middle line, in geometric order.
    mid = np.array(PRR3_MIDDLE_LINE) - 1
    np.testing.assert_array_equal(P[mid, 0], m.h / 2)
    assert np.all(np.diff(P[mid, 1]) < 0)
    others = np.setdiff1d(np.arange(22), mid)
    assert np.all(P[others, 0] != m.h / 2)
    mp = m.evaluate(P)
    assert mp.valid.all()
    s, p = m.singularity_measures(P)
    assert s.min() >= 0.25 and p.min() >= 0.25
    np.testing.assert_array_equal(preset_points("points22"), P)
    assert position_presets()["points22"][0] == "3prr" and position_presets()["paper48"][0] == "delta"


def test_paper48_grid():
    P = paper48()
    assert P.shape == (48, 3)
    for z in (-200.0, -310.0, -400.0):
        plane = P[P[:, 2] == z]
        assert plane.shape == (16, 3)
        np.testing.assert_allclose(np.unique(plane[:, 0]), [-200, -200 / 3, 200 / 3, 200], atol=1e-12)
        np.testing.assert_allclose(np.unique(plane[:, 1]), [-200, -200 / 3, 200 / 3, 200], atol=1e-12)
    with pytest.raises(ValueError, match="unknown position preset 'grid9'; valid: paper48, points22"):
        preset_points("grid9")


def test_unreachable_and_off_rail_poses_are_named():
    m = PRR3()
    with pytest.raises(PoseError, match=r"pose \(400, 800\) mm unreachable: .*off its rail"):
        m.stiffness([400.0, 800.0])
    with pytest.raises(PoseError, match=r"pose \(-500, 0\) mm unreachable: .*rod 2 too short"):
        m.static_error([-500.0, 0.0], [0.0, 100.0])
    mp = m.evaluate([[400.0, 200.0], [400.0, 800.0], [-500.0, 0.0]])
    np.testing.assert_array_equal(mp.valid, [True, False, False])
    assert mp.reasons[0] == "" and mp.reasons[1].startswith("unreachable: rod 1 too short")
    assert np.all(np.isnan(mp.K[1:])) and np.all(np.isfinite(mp.K[0]))
    assert np.all(np.isnan(mp.q[1:]))


def test_rod_perpendicular_to_its_rail_is_flagged_singular():
    # A rod perpendicular to its rail (n_i . u_i = 0) is the edge of the workspace: the slider
    # cannot move the tool along the rod. Within the default rails' stroke this happens with the
    # slider at the rail's end (the centre), the tool a rod length L beside it.
    m = PRR3()
    for i in range(3):
        u = m.rail_directions[i]
        uperp = np.array([-u[1], u[0]])
        S = m.vertices[i] + (m.rail_length - 1e-6) * u
        for side in (1.0, -1.0):
            T = S + side * (1 - 1e-9) * m.L * uperp
            s, _ = m.singularity_measures(T)
            assert s[0] < 1e-3
            mp = m.evaluate(T)
            assert not mp.valid[0]
            assert mp.reasons[0].startswith(f"singular: rod {i + 1} perpendicular to its rail")
            with pytest.raises(
                PoseError, match=f"rod {i + 1} perpendicular to its rail .*serial singularity"
            ):
                m.stiffness(T)
            # 2 mm towards the centre the pose is regular again.
            assert m.evaluate(T + 2.0 * (m.centre - T) / np.linalg.norm(m.centre - T)).valid[0]


@pytest.mark.parametrize("name", ["h", "L", "area", "E", "kj", "kb"])
@pytest.mark.parametrize("bad", [0.0, -3.0, math.inf, math.nan])
def test_non_positive_parameters_are_refused(name, bad):
    with pytest.raises(ValueError, match=f"{name} must be a positive number"):
        PRR3().with_params(**{name: bad})


def test_unknown_parameter_names_are_listed():
    with pytest.raises(ValueError, match=r"unknown 3PRR parameter\(s\) Kj; valid: h, L, area, E, kj, kb"):
        PRR3().with_params(Kj=500.0)
