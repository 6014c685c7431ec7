"""Parallel robots from their legs (virtual joint method): the assembly, LegRobot, the built-ins."""

from __future__ import annotations

import json
import math
import tempfile
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers.fuzz_campaign import mutated_spec, toml_text_mutations
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.cli.main import main
from stiffmap.errors import InputError
from stiffmap.models import PRR3, DeltaRobot, Mechanism, PoseError
from stiffmap.models.base import constrained_directions, leg_stiffness
from stiffmap.models.fit import fit_stiffness
from stiffmap.models.legs import LegRobot
from stiffmap.models.legs_convert import legs_toml

ROBOTS = files("stiffmap.models") / "robots"
DELTA_BOX = ((-200.0, -200.0, -400.0), (200.0, 200.0, -200.0))  # holds the paper48 grid
PRR3_BOX = ((150.0, 0.0), (650.0, 460.0))  # holds the 22-point layout


def _from_legs(name: str) -> LegRobot:
    return LegRobot.from_toml(ROBOTS / f"{name}.toml")


def _relative(K, K_ref) -> np.ndarray:
    return np.abs(K - K_ref).max(axis=(-2, -1)) / np.abs(K_ref).max(axis=(-2, -1))


# ---------------------------------------------------------------------- the assembly


def test_leg_stiffness_frees_the_passive_directions(rng):
    # K_leg = U (U^T C U)^-1 U^T over the directions the passive joints hold, with a zero and a
    # repeated passive column (a ball joint's spin, dependent axes) among them.
    for d, s, p in ((3, 4, 1), (3, 3, 2), (2, 3, 1), (3, 4, 0)):
        Js = rng.normal(scale=100.0, size=(d, s))
        k = rng.uniform(1e3, 1e5, size=s)
        Jp = rng.normal(scale=100.0, size=(d, p))
        Jp = np.concatenate([Jp, np.zeros((d, 1)), Jp[:, :1] * 2.0], axis=1) if p else Jp
        U, held = constrained_directions(Jp)
        assert held.sum() == d - p
        K, rigid = leg_stiffness(Js, k, U, held)
        C = Js @ np.diag(1 / k) @ Js.T
        if p == 0:
            np.testing.assert_allclose(K, np.linalg.inv(C), rtol=1e-12)  # no passive joint: C^-1
        # The same by another route: the pseudo-inverse of C projected off range(J_p) (SVD).
        Pj = np.eye(d) - Jp @ np.linalg.pinv(Jp)
        np.testing.assert_allclose(K, np.linalg.pinv(Pj @ C @ Pj), rtol=0, atol=1e-10 * np.abs(K).max())
        np.testing.assert_array_equal(K, K.T)
        assert not rigid and np.linalg.matrix_rank(K, tol=1e-9 * np.abs(K).max()) == d - p


def test_a_leg_without_compliance_along_a_held_direction_is_rigid():
    Js = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    Jp = np.array([[0.0], [0.0], [1.0]])
    U, held = constrained_directions(Jp)
    _, rigid = leg_stiffness(Js, [1e3, 1e3], U, held)
    assert not rigid
    K, rigid = leg_stiffness(Js, [1e3, math.inf], U, held)  # y held by a rigid spring only
    assert rigid and np.all(np.isnan(K))


def test_builtin_stiffness_is_the_closed_form_leg_formula(rng):
    # The built-ins assemble K from their legs' joint columns; the closed forms of their
    # docstrings (each leg a spring along its two-force member) must come out.
    d = DeltaRobot(k_theta=2.3e5, k_arm=900.0, k_forearm=7000.0)
    P = rng.uniform(*DELTA_BOX, size=(50, 3))
    L = d.legs(P)
    nt = np.einsum("nij,nij->ni", L.n, L.t)
    k_leg = 1 / (nt**2 / d.k_theta + (nt / d.arm_length) ** 2 / d.k_arm + 1 / d.k_forearm)
    K = np.einsum("ni,nij,nik->njk", k_leg, L.n, L.n)
    np.testing.assert_allclose(d.stiffness(P), K, rtol=1e-12, atol=1e-12 * np.abs(K).max())
    m = PRR3(kj=700.0, kb=5000.0, E=2.1e5, area=50.0)
    T = rng.uniform(*PRR3_BOX, size=(200, 2))
    T = T[m.evaluate(T).valid]
    lg = m.legs(T)
    a = np.einsum("nij,ij->ni", lg.n, lg.u)
    c = lg.n[..., 0] * lg.u[:, 1] - lg.n[..., 1] * lg.u[:, 0]  # n . u_perp up to sign
    k_leg = 1 / (a * a / m.kj + c * c / m.kb + m.L / (m.E * m.area))
    K = np.einsum("ni,nij,nik->njk", k_leg, lg.n, lg.n)
    np.testing.assert_allclose(m.stiffness(T), K, rtol=1e-12, atol=1e-12 * np.abs(K).max())


# ---------------------------------------------------------------------- the built-ins rebuilt


def test_shipped_leg_files_are_what_legs_toml_writes():
    assert (ROBOTS / "delta.toml").read_text(encoding="utf-8") == legs_toml(DeltaRobot())
    assert (ROBOTS / "3prr.toml").read_text(encoding="utf-8") == legs_toml(PRR3())


def test_delta_rebuilt_from_its_legs_equals_the_builtin(rng):
    # Generic chains (Pinocchio) and numeric IK: an independent route from the closed forms.
    lr = _from_legs("delta")
    assert isinstance(lr, Mechanism) and (lr.name, lr.dim) == ("delta", 3)
    k = dict(k_theta=rng.uniform(1e5, 5e5), k_arm=rng.uniform(300, 3000), k_forearm=rng.uniform(2e3, 5e4))
    for params in ({}, k):
        P = rng.uniform(*DELTA_BOX, size=(10, 3))
        ref = DeltaRobot(**params).evaluate(P)
        m = lr.with_params(**params).evaluate(P)
        np.testing.assert_array_equal(m.valid, ref.valid)
        assert ref.valid.sum() >= 8
        v = ref.valid
        assert _relative(m.K[v], ref.K[v]).max() < 1e-9
        np.testing.assert_allclose(m.q[v], ref.q[v], rtol=0, atol=1e-9)  # actuator angles, rad
    # Near the base, far from the seed, the IK's direct solve lands on the elbow-in branch; the
    # elbow's limits (the elbow-out branch) send it back along a path from the seed.
    far = np.array(
        [[180.6, 8.9, -135.4], [261.5, -19.4, -143.7], [142.7, 224.8, -109.1], [22.5, 219.3, -101.5]]
    )
    assert _relative(lr.stiffness(far), DeltaRobot().stiffness(far)).max() < 1e-9
    # Singularity measures: the same parallel one; the serial one is the sine between n and the
    # actuator's column at the platform joint, w x (C - A), where the built-in takes t.
    s, p = lr.singularity_measures(P[v])
    s_ref, p_ref = DeltaRobot().singularity_measures(P[v])
    np.testing.assert_allclose(p, p_ref, rtol=1e-9)
    L = DeltaRobot().legs(P[v])
    w = np.stack([-np.sin(DeltaRobot().leg_angles), np.cos(DeltaRobot().leg_angles), np.zeros(3)], axis=1)
    col = np.cross(w[None], L.C - L.A)
    sine = np.abs(np.einsum("nij,nij->ni", L.n, col)) / np.linalg.norm(col, axis=2)
    np.testing.assert_allclose(s, sine.min(axis=1), rtol=1e-9)


def test_3prr_rebuilt_from_its_legs_equals_the_builtin(rng):
    lr = _from_legs("3prr")
    assert (lr.name, lr.dim) == ("3prr", 2)
    kj, kb, E, area = (
        rng.uniform(200, 2000),
        rng.uniform(2000, 3e4),
        rng.uniform(2e4, 2.1e5),
        rng.uniform(20, 400),
    )
    ref_model = PRR3(kj=kj, kb=kb, E=E, area=area)
    T = rng.uniform(*PRR3_BOX, size=(20, 2))
    ref = ref_model.evaluate(T)
    m = lr.with_params(kj=kj, kb=kb, k_rod=E * area / ref_model.L).evaluate(T)
    np.testing.assert_array_equal(m.valid, ref.valid)  # the same workspace (the rails as limits)
    assert ref.valid.sum() >= 12
    v = ref.valid
    assert _relative(m.K[v], ref.K[v]).max() < 1e-9
    np.testing.assert_allclose(m.q[v], ref.q[v], rtol=0, atol=1e-7)  # slider positions, mm
    s, p = lr.singularity_measures(T[v])
    s_ref, p_ref = ref_model.singularity_measures(T[v])
    np.testing.assert_allclose(s, s_ref, rtol=1e-9)
    np.testing.assert_allclose(p, p_ref, rtol=1e-9)


def _urdf_leg(m: PRR3, i: int) -> str:
    """Leg i of the 3PRR as a URDF (metres), its springs as prismatic joints."""
    V, u = m.vertices[i] / 1000, m.rail_directions[i]
    g = math.atan2(u[1], u[0])
    joints = [
        ("slider", "prismatic", f"{V[0]} {V[1]} 0", f"0 0 {g}", "1 0 0", (0, m.rail_length / 1000)),
        ("bearing", "prismatic", "0 0 0", "0 0 0", "0 1 0", (0, 0)),
        ("pin_slider", "revolute", "0 0 0", "0 0 0", "0 0 1", (-math.pi / 2, math.pi / 2)),
        ("rod", "prismatic", "0 0 0", "0 0 0", "1 0 0", (0, 0)),
        ("pin_tool", "revolute", f"{m.L / 1000} 0 0", "0 0 0", "0 0 1", (-math.pi, math.pi)),
    ]
    out = ['<robot name="prr_leg">', '<link name="l0"/>']
    for k, (name, kind, xyz, rpy, axis, (lo, hi)) in enumerate(joints, start=1):
        out += [
            f'<link name="l{k}"/>',
            f'<joint name="{name}" type="{kind}"><parent link="l{k - 1}"/><child link="l{k}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/></joint>',
        ]
    return "\n".join(out + ["</robot>"])


def test_legs_given_as_urdfs_equal_the_builtin(rng, tmp_path):
    m = PRR3()
    l0 = m.rail_length - m.L
    for i in range(3):
        (tmp_path / f"leg{i + 1}.urdf").write_text(_urdf_leg(m, i))
    text = "dim = 2\n[params]\nkj = 525.0\nkb = 9800.0\nk_rod = 56000.0\n"
    for i in range(3):
        text += (
            f'[[legs]]\nurdf = "leg{i + 1}.urdf"\ntip_frame = "l5"\nattach_mm = [0.0, 0.0]\n'
            f'[[legs.joints]]\nname = "slider"\nrole = "actuated"\nstiffness = "kj"\nq0 = {l0}\n'
            '[[legs.joints]]\nname = "bearing"\nrole = "spring"\nstiffness = "kb"\n'
            '[[legs.joints]]\nname = "rod"\nrole = "spring"\nstiffness = "k_rod"\n'
        )  # the pins are not listed: passive, seed 0, the URDF's limits
    (tmp_path / "urdf3prr.toml").write_text(text)
    lr = LegRobot.from_toml(tmp_path / "urdf3prr.toml")
    assert lr.roles[0] == ("actuated", "spring", "passive", "spring", "passive")
    T = rng.uniform(*PRR3_BOX, size=(10, 2))
    ref = m.evaluate(T)
    got = lr.evaluate(T)
    np.testing.assert_array_equal(got.valid, ref.valid)
    v = ref.valid
    assert v.sum() >= 5 and _relative(got.K[v], ref.K[v]).max() < 1e-9
    with pytest.raises(
        InputError, match=r"legs\[1\]\.joints\[1\]\.name: 'slidr' is not a joint moving 'l5' in"
    ):
        LegRobot.from_toml_text(text.replace('name = "slider"', 'name = "slidr"', 2), base_dir=tmp_path)
    with pytest.raises(
        InputError, match=r"^legs\.toml: legs\[1\]\.urdf: .*leg1\.urdf: no frame 'l9' for the measured point"
    ):
        LegRobot.from_toml_text(text.replace('"l5"', '"l9"', 1), base_dir=tmp_path)


def _leg_force(chain, q_ik, springs, passive, k, target, d):
    """The force (N) a leg's tip exerts when held at ``target``: the spring deflections and passive
    joints at equilibrium (min 1/2 s^T diag(k) s with the tip on target; the KKT conditions solved by
    Gauss-Newton steps on the chain), the constraint's multiplier."""
    q = q_ik.copy()
    for _ in range(50):
        r = target - chain.forward(q)[0][:d]
        J = chain.jacobian(q)[:d]
        Js, Jp = J[:, springs], J[:, passive]
        ns, npas = len(springs), len(passive)
        A = np.zeros((ns + npas + d, ns + npas + d))
        A[:ns, :ns] = np.diag(k)
        A[:ns, ns + npas :] = -Js.T
        A[ns : ns + npas, ns + npas :] = -Jp.T
        A[ns + npas :, :ns] = Js
        A[ns + npas :, ns : ns + npas] = Jp
        rhs = np.concatenate([-k * (q[springs] - q_ik[springs]), np.zeros(npas), r])
        x = np.linalg.lstsq(A, rhs, rcond=None)[0]  # min-norm: a zero passive column stays put
        q[springs] += x[:ns]
        q[passive] += x[ns : ns + npas]
        if np.abs(r).max() < 1e-13 and np.abs(x[: ns + npas]).max() < 1e-15:
            break
    return x[ns + npas :]


@pytest.mark.parametrize("name", ["delta", "3prr"])
def test_leg_robot_stiffness_matches_force_balance_of_its_legs(name):
    # Independent of the assembly: push each leg's platform joint by +-h along each axis, find its
    # spring deflections at equilibrium on the nonlinear chain (passive joints free), and take the
    # central difference of the force it exerts; the legs' stiffnesses add at the tool point.
    lr = _from_legs(name)
    if name == "delta":
        lr = lr.with_params(k_arm=1500.0, k_forearm=20000.0)
        P = np.array([40.0, -70.0, -330.0])
    else:
        P = np.array([380.0, 250.0])
    st = lr.legs(P)
    d, h = lr.dim, 1e-4
    K = np.zeros((d, d))
    for chain, roles, desc, q in zip(lr.chains, lr.roles, lr.description, st.joints, strict=True):
        roles = np.array(roles)
        springs, passive = np.flatnonzero(roles != "passive"), np.flatnonzero(roles == "passive")
        k = np.array([lr.params()[j.stiffness] for j in desc.joints if j.role != "passive"])
        tip = chain.forward(q[0])[0][:d]
        for j in range(d):
            e = h * np.eye(d)[j]
            f = [_leg_force(chain, q[0], springs, passive, k, tip + sg * e, d) for sg in (1, -1)]
            K[:, j] += (f[0] - f[1]) / (2 * h)
    np.testing.assert_allclose(lr.stiffness(P), K, rtol=1e-6, atol=1e-7 * np.abs(K).max())


# ---------------------------------------------------------------------- behaviour, files, errors


def test_leg_robot_flags_unreachable_poses_naming_the_leg():
    lr = _from_legs("3prr")
    m = lr.evaluate([[400.0, 220.0], [400.0, 900.0], [50.0, 0.0]])
    np.testing.assert_array_equal(m.valid, [True, False, False])
    assert m.reasons[1].startswith("unreachable: leg 1 (leg1) cannot reach it from its seed")
    # Near vertex 1, slider 1 would sit 205 mm before its rail starts: moving there from the
    # seed, it leaves its rail (the built-in: "slider 1 off its rail (l1 = -205.4 mm ...)").
    assert m.reasons[2].startswith(
        "unreachable: leg 1 (leg1) cannot reach it from its seed within its limits (joint slider at -"
    )
    assert "beyond its limits [0, 461.88] mm" in m.reasons[2]
    with pytest.raises(PoseError, match=r"point 1: pose \(400, 900\) mm unreachable: leg 1"):
        lr.stiffness([[400.0, 220.0], [400.0, 900.0]])


def test_leg_robot_params_fit_and_write_back(tmp_path):
    lr = _from_legs("delta")
    assert lr.params() == {"k_theta": 2.77e5, "k_arm": math.inf, "k_forearm": math.inf}
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) ktheta of delta; valid: k_theta, k_arm"):
        lr.with_params(ktheta=1.0)
    with pytest.raises(ValueError, match="k_theta must be a positive number"):
        lr.with_params(k_theta=math.inf)  # an actuator is not rigid
    # Fitted by name like a built-in: k_theta from the built-in's matrices.
    P = np.array([[0.0, 0.0, -300.0], [150.0, -100.0, -250.0], [-120.0, 60.0, -380.0]])
    fit = fit_stiffness(lr, P, DeltaRobot(k_theta=1.9e5).stiffness(P), params=("k_theta",))
    assert fit.values["k_theta"] == pytest.approx(1.9e5, rel=1e-8)
    # Written back with its parameters, read again: the same robot.
    text = legs_toml(lr.with_params(k_arm=800.0))
    again = LegRobot.from_toml_text(text, source="again.toml")
    assert again.params() == {"k_theta": 2.77e5, "k_arm": 800.0, "k_forearm": math.inf}
    K_ref = DeltaRobot(k_arm=800.0).stiffness(P)
    assert _relative(again.stiffness(P), K_ref).max() < 1e-9


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "axis = [0.0, 1.0, 0.0]",
            "axis = [0.0, 1.0]",
            r"legs\[1\]\.joints\[1\]\.axis: expected three numbers",
        ),
        (
            'stiffness = "k_theta"',
            'stiffness = "k_thta"',
            r"legs\[1\]\.joints\[1\]\.stiffness: 'k_thta' is not in \[params\] \(k_theta, k_arm, k_forearm\)",
        ),
        (
            'name = "elbow_z"\ntype = "revolute"',
            'name = "elbow_z"\nstifness = "k"\ntype = "revolute"',
            r"legs\[1\]\.joints\[5\]\.stifness: unknown key \(expected one of name, role, stiffness",
        ),
        ("dim = 3", "dim = 4", r"dim: Input should be 2, 3 or 6, got 4"),
        (
            "attach_mm = [0.0, 40.0, 0.0]",
            "attach_mm = [0.0, 40.0]",
            r"legs\[1\]\.attach_mm: expected 3 numbers",
        ),
        ("k_forearm = inf", "k_forearm = inf\nk_spare = 5.0", r"params\.k_spare: no joint refers to it"),
        (
            'role = "spring"\nstiffness = "k_arm"',
            'role = "spring"\nstiffness = "k_arm"\nq0 = 0.1',
            r"legs\[1\]\.joints\[2\]\.q0: a spring joint stays at rest",
        ),
        (
            'role = "passive"\nq0 = 0.0',
            'role = "passive"\nstiffness = "k_arm"\nq0 = 0.0',
            r"legs\[1\]\.joints\[4\]\.stiffness: a passive joint is free",
        ),
        ("k_theta = 277000.0", "k_theta = -1.0", r"params\.k_theta: a stiffness must be positive"),
        ("dim = 3", "dim = [", r"not valid TOML"),
    ],
)
def test_bad_leg_files_are_named(old, new, message):
    text = (ROBOTS / "delta.toml").read_text(encoding="utf-8")
    assert old in text
    with pytest.raises(InputError, match=r"^bad\.toml: " + message):
        LegRobot.from_toml_text(text.replace(old, new, 1), source="bad.toml")


@pytest.mark.fuzz
@given(data=st.data())
def test_mutated_leg_files_load_or_are_refused_by_name(data):
    name = data.draw(st.sampled_from(["delta", "3prr"]))
    valid = (ROBOTS / f"{name}.toml").read_text(encoding="utf-8")
    raw = data.draw(st.one_of(mutated_spec(valid), mutated_spec(valid), toml_text_mutations(valid)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.toml"
        path.write_bytes(raw)
        try:
            lr = LegRobot.from_toml(path)
        except InputError as e:
            assert str(e).startswith(f"{path}: ")
            return
    m = lr.evaluate(np.array([[0.0, 0.0, -300.0]]) if lr.dim == 3 else np.array([[400.0, 230.0]]))
    assert m.valid[0] or m.reasons[0].startswith(("unreachable: ", "singular: "))


def test_the_docs_example_is_a_3rpr_with_the_hand_stiffness(rng):
    # docs/models.md, "The legs TOML": each leg a two-force member along its length, so
    # K = k_leg sum_i n_i n_i^T with n_i the unit vector from base pin i to the tool.
    doc = (Path(__file__).resolve().parents[1] / "docs" / "models.md").read_text(encoding="utf-8")
    section = doc[doc.index("### The legs TOML") :]
    text = section[section.index("```toml\n") + 8 : section.index("```\n", section.index("```toml"))]
    lr = LegRobot.from_toml_text(text, source="docs/models.md")
    assert (lr.name, lr.dim, lr.params()) == ("3rpr", 2, {"k_leg": 2000.0})
    T = rng.uniform((200.0, 100.0), (400.0, 250.0), size=(8, 2))
    n = T[:, None, :] - np.array([[0.0, 0.0], [600.0, 0.0], [300.0, 519.6]])
    q = np.linalg.norm(n, axis=2)
    n /= q[..., None]
    K = 2000.0 * np.einsum("nij,nik->njk", n, n)
    assert _relative(lr.stiffness(T), K).max() < 1e-9
    np.testing.assert_allclose(lr.inverse_kinematics(T).q, q, atol=1e-7)  # leg lengths, mm


def test_model_legs_command_prints_the_leg_described_robot(tmp_path, capsys):
    """`stiffmap model legs ROBOT.toml --points ... --json`: the Delta's TOML gives the Delta's K;
    a missing TOML and missing positions are named."""
    pts = tmp_path / "pts.csv"
    pts.write_text("x,y,z\n0,0,-300\n50,20,-250\n")
    code = main(["model", "legs", str(ROBOTS / "delta.toml"), "--points", str(pts), "--json"])
    out = capsys.readouterr().out
    assert code in (0, None)
    recs = json.loads(out)
    K = DeltaRobot().stiffness(np.array([[0.0, 0.0, -300.0], [50.0, 20.0, -250.0]]))
    np.testing.assert_allclose(np.array([r["K"] for r in recs]), K, rtol=1e-6, atol=1e-9 * np.abs(K).max())
    assert main(["model", "legs", "--points", str(pts)]) == 2
    assert "needs the robot's legs TOML file" in capsys.readouterr().err
    assert main(["model", "legs", str(ROBOTS / "delta.toml")]) == 2
    assert "give the positions" in capsys.readouterr().err
