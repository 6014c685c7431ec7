"""Fuzz tests of the robot descriptions (helpers.fuzz_robots): legs TOMLs (dim 2, 3, 6), the
hexapod's and the 3-RPS's poses CSV and options, URDF, xacro, configurations CSV, ``simulate
--robot`` (the 3-RPS with odd --positions among them).

Each class is one hypothesis test: the command succeeds with the right answer where it can be
computed independently (the closed-form K6 of UPS legs, helpers.urdf_reference for a URDF; the
JSON then holds only finite numbers) or ends with one clear message naming the file (exit 1 or
2). ``pytest -m fuzz tests/test_fuzz_robots.py`` runs the long profile; the default run takes 3
examples of each class (1 of ``simulate --robot``). Below them, the misbehaviours the fuzzing
found, as regression tests.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from helpers import fuzz_robots as fr
from helpers.fuzz import assert_handled, run_argv, run_case
from hypothesis import given, settings

pytestmark = pytest.mark.fuzz

_BY_NAME = {c.name: c for c in fr.FUZZ_CLASSES}

#: The current profile's number of examples, at most 3 in the default run (conftest: 12).
_EXAMPLES = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 3)
_ONE = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 1)


def _check(case):
    o = run_case(case)
    assert_handled(case, o)
    return o


@_EXAMPLES
@given(case=_BY_NAME["robots: legs TOML x model legs"].cases)
def test_legs_tomls(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["robots: poses CSV x model legs"].cases)
def test_poses_and_options_of_a_hexapod(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["robots: URDF x model urdf"].cases)
def test_urdfs(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["robots: xacro x model urdf"].cases)
def test_xacro_descriptions(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["robots: configurations CSV x model urdf"].cases)
def test_configurations(case):
    _check(case)


@_ONE
@given(case=_BY_NAME["robots: robot file x simulate --robot"].cases)
def test_simulate_robot_files(case):
    _check(case)


# ------------------------------------------------------------------------ the oracles can fail
def _valid_hexapod_case() -> fr.RobotCase:
    text = (fr.SHIPPED / "hexapod.toml").read_bytes()
    argv = ("model", "legs", "{dir}/hexapod.toml", *fr.LEGS_SEEDS["hexapod.toml"], "--json")
    return fr.RobotCase({"hexapod.toml": text}, argv, "hexapod.toml", oracle=fr.legs_check(text))


def test_the_hexapod_oracle_accepts_the_model_and_refuses_a_K6_off_by_a_percent():
    case = _valid_hexapod_case()
    o = run_case(case)
    assert o.kind == "ok", o.stderr
    recs = json.loads(o.stdout)
    assert len(recs) == 4 and all(r["K6"] is not None for r in recs)
    for r in recs:
        r["K6"][2][2] *= 1.01  # a leg's stiffness misread by 1 % in z
    o.stdout = json.dumps(recs)
    assert "differs from the closed form" in case.oracle(o)


def test_the_urdf_oracle_accepts_the_model_and_refuses_a_point_moved_by_a_micrometre():
    seed = "acme_rs6.urdf"
    tip, base, rows = fr.URDF_SEEDS[seed]
    data = (fr.TEST_ROBOTS / seed).read_bytes()
    case = fr.RobotCase(
        {seed: data, "q.csv": fr._configs_text(rows).encode()},
        fr._urdf_argv(seed, tip, base),
        None,
        oracle=fr.urdf_check(data, tip, base, np.array(rows), fr.OFFSET_MM, fr.K_ALL),
    )
    o = run_case(case)
    assert o.kind == "ok", o.stderr
    recs = json.loads(o.stdout)
    recs[1]["position"][0] += 1e-3
    o.stdout = json.dumps(recs)
    assert "configuration 2: position" in case.oracle(o)


def test_the_3rps_oracle_accepts_the_model_and_refuses_a_K6_off_or_a_pose_it_does_not_hold():
    # The three poses the independent solver (helpers.poses.rps_pose) says the shipped 3-RPS holds:
    # exit 0, and each K6 the closed form of its legs and bending springs (rps3_k6, 1e-5).
    rows = fr.rps3_poses()
    case = fr.RobotCase(
        {"3rps.toml": (fr.SHIPPED / "3rps.toml").read_bytes(), "poses.csv": fr._pose_text(rows).encode()},
        ("model", "legs", "{dir}/3rps.toml", "--points", "{dir}/poses.csv", "--json"),
        "poses.csv",
        oracle=fr.rps3_check(),
    )
    o = run_case(case)
    assert o.kind == "ok", o.stderr
    recs = json.loads(o.stdout)
    assert len(recs) == 3 and all(r["K6"] is not None for r in recs)
    bent = json.loads(o.stdout)
    bent[1]["K6"][0][0] *= 1.01  # K6 off by 1 % along x
    o.stdout = json.dumps(bent)
    assert "differs from the closed form" in case.oracle(o)
    moved = json.loads(json.dumps(recs))
    moved[2]["x"] += 1e-3  # a pose 1 um off the one it holds, printed with a K6
    o.stdout = json.dumps(moved)
    assert "pose 3 printed with a K6: a ball joint" in case.oracle(o)
    del moved[2]["K6"]  # left without a K6 and without a reason
    o.stdout = json.dumps(moved)
    assert case.oracle(o) == "pose 3: no K6 and no reason"


def test_every_class_is_tested():
    assert set(_BY_NAME) == {
        "robots: legs TOML x model legs",
        "robots: poses CSV x model legs",
        "robots: URDF x model urdf",
        "robots: xacro x model urdf",
        "robots: configurations CSV x model urdf",
        "robots: robot file x simulate --robot",
    }


# ------------------------------------------------------------------------ findings
def _with_copied_leg(seed: str, src: int, dst: int) -> bytes:
    """The shipped TOML with leg ``dst`` (0-based) a copy of leg ``src`` under its own name and
    stiffness names: a copied leg not edited."""
    data = json.loads(json.dumps(fr.legs_seed(seed), allow_nan=True))
    legs = data["legs"]
    copy = json.loads(json.dumps(legs[src], allow_nan=True))
    copy["name"] = legs[dst]["name"]
    for a, b in zip(copy["joints"], legs[dst]["joints"], strict=True):
        if "stiffness" in b:
            a["stiffness"] = b["stiffness"]
    legs[dst] = copy
    return fr.toml_text(data).encode()


@pytest.mark.parametrize("seed", ["3prr.toml", "delta.toml", "hexapod.toml"])
def test_two_legs_in_the_same_place_are_refused_naming_both(tmp_path, seed):
    """Found by the fuzzing: a 3PRR whose third leg is a copy of its second gave exit 0 and a K
    that counts one leg twice (the Delta and the hexapod: every point singular, the file not
    named)."""
    f = tmp_path / seed
    f.write_bytes(_with_copied_leg(seed, 1, 2))
    o = run_argv(["model", "legs", str(f), *fr.LEGS_SEEDS[seed], "--json"])
    assert o.code == 2, (o.code, o.stdout[:500])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and seed in lines[0], o.stderr
    assert "legs[3]" in lines[0] and "same place as legs[2]" in lines[0], lines[0]


def test_the_shipped_files_legs_are_all_in_different_places():
    for seed in ("3prr.toml", "delta.toml", "hexapod.toml", "3rps.toml", "delta_links.toml"):
        o = run_argv(["model", "legs", str(fr.SHIPPED / seed), "--grid", "0,0,0", "--json"])
        assert "same place" not in o.stderr, (seed, o.stderr)


@pytest.mark.parametrize(("grid", "orientation"), fr.TOO_MANY_POSES[:2])
def test_a_grid_at_orientations_of_too_many_poses_is_refused(grid, orientation):
    """Found by the fuzzing: --grid and --orientation each within their limits (a million
    positions, 1e5 orientations) joined into 1e11 poses: an internal error (MemoryError
    allocating 2.18 TiB), or 1e8 poses allocated and mapped for days."""
    hexapod = str(fr.SHIPPED / "hexapod.toml")
    o = run_argv(["model", "legs", hexapod, f"--grid={grid}", f"--orientation={orientation}", "--json"])
    assert o.code == 2 and o.escaped is None, (o.code, o.stderr[-500:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --grid with --orientation gives"), o.stderr
    n_pos, n_or = (int(w) for w in re.findall(r"(\d+) (?:positions|orientations)", lines[0]))
    assert n_pos * n_or > 1_000_000 and f"{n_pos * n_or} poses; at most 1000000" in lines[0]


@pytest.mark.parametrize(("multiplier", "offset"), [("1e300", "0"), ("-2e6", "0"), ("1", "1e300")])
def test_a_mimic_of_absurd_multiplier_or_offset_on_the_chain_is_refused(tmp_path, multiplier, offset):
    """Found by the fuzzing: <mimic multiplier="1e300"> on the chain was an internal error
    (RuntimeWarning: overflow encountered in dot)."""
    text = (fr.TEST_ROBOTS / "acme_rs6.urdf").read_text()
    follower = f'<mimic joint="joint_1" multiplier="{multiplier}" offset="{offset}"/>'
    text = text.replace(
        '<joint name="joint_3" type="revolute">', f'<joint name="joint_3" type="revolute">{follower}'
    )
    f = tmp_path / "acme_rs6.urdf"
    f.write_text(text)
    q = tmp_path / "q.csv"
    q.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg\n10,20,30,40,50\n")
    o = run_argv(["model", "urdf", str(f), "--tip", "tool0", "--configs", str(q), "--param", "k_theta=1e7"])
    assert o.code == 2, (o.code, o.stderr[-500:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "acme_rs6.urdf" in lines[0] and "joint 'joint_3'" in lines[0], o.stderr
    assert "<mimic multiplier>" in lines[0] or "<mimic offset>" in lines[0], lines[0]


def test_a_mimic_of_a_moderate_multiplier_is_still_followed(tmp_path):
    # a mimic within the bounds is followed: the model runs and agrees with the reference
    text = (fr.TEST_ROBOTS / "acme_rs6.urdf").read_text()
    follower = '<mimic joint="joint_2" multiplier="-0.5" offset="0.1"/>'
    text = text.replace(
        '<joint name="joint_3" type="revolute">', f'<joint name="joint_3" type="revolute">{follower}'
    )
    rows = ((10.0, 20.0, 40.0, 50.0, 60.0),)
    case = fr.RobotCase(
        {"acme_rs6.urdf": text.encode(), "q.csv": fr._configs_text(rows).encode()},
        fr._urdf_argv("acme_rs6.urdf", "tool0", None),
        None,
        oracle=fr.urdf_check(text.encode(), "tool0", None, np.array(rows), fr.OFFSET_MM, fr.K_ALL),
    )
    o = run_case(case)
    assert o.kind == "ok", o.stderr


def _misspelt_parent(path, parent: str, child: str, misspelt: str) -> None:
    """The test robot written to ``path`` with ``child``'s parent link misspelt, and a link of
    that name added so the file still reads (a second root)."""
    text = (fr.TEST_ROBOTS / "acme_rs6.urdf").read_text()
    joint = f'<parent link="{parent}"/><child link="{child}"/>'
    assert joint in text
    text = text.replace(joint, f'<parent link="{misspelt}"/><child link="{child}"/>')
    path.write_text(text.replace('<link name="world"/>', f'<link name="world"/><link name="{misspelt}"/>'))


def test_a_urdf_of_two_roots_is_said_and_the_root_used_named(tmp_path):
    """Found by the fuzzing: joint_1's parent link misspelt (a link of that name added: the file
    reads) made link 'base_lnk' a second root; the chain started there, 0.4 m below the robot's
    'world', with exit 0 and no word (the positions 400 mm off)."""
    _misspelt_parent(tmp_path / "acme_rs6.urdf", "base_link", "link_1", "base_lnk")
    (tmp_path / "q.csv").write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,20,-30,40,50,60\n")
    argv = [
        "model",
        "urdf",
        str(tmp_path / "acme_rs6.urdf"),
        "--tip",
        "tool0",
        "--configs",
        str(tmp_path / "q.csv"),
    ]
    o = run_argv([*argv, "--param", "k_theta=1e7", "--json"])
    assert o.code == 1, (o.code, o.stderr)
    lines = [ln for ln in o.stderr.splitlines() if ln.startswith("warning:")]
    assert len(lines) == 1 and "acme_rs6.urdf: 2 root links ('world', 'base_lnk')" in lines[0], o.stderr
    assert "starts at 'base_lnk'" in lines[0]
    shipped = [str(fr.TEST_ROBOTS / "acme_rs6.urdf") if a.endswith("acme_rs6.urdf") else a for a in argv]
    good = run_argv([*shipped, "--param", "k_theta=1e7", "--json"])
    assert good.code == 0 and not good.stderr.strip(), good.stderr
    z = [json.loads(x.stdout)[0]["position"][2] for x in (o, good)]
    assert z[1] - z[0] == pytest.approx(400.0, abs=1e-9)  # what the warning is about: the pedestal
    chosen = run_argv([*argv, "--base", "base_lnk", "--param", "k_theta=1e7"])  # the user said which
    assert chosen.code == 0 and "root links" not in chosen.stderr, chosen.stderr


@pytest.mark.parametrize(
    "argv",
    [
        ["model", "delta", "--grid", "0,0,1e300"],
        ["model", "legs", "hexapod", "--grid", "0,0,1e300", "--json"],
        ["model", "legs", "hexapod", "--grid=0,0,1e300", "--orientation=-10:10:3,0,0"],
        ["model", "legs", "delta", "--grid", "-2e6:0:3,0,-300"],
    ],
)
def test_a_grid_beyond_a_plausible_position_is_an_error_of_the_option(argv):
    """Found by the fuzzing: --grid 0,0,1e300 was an internal error (ValueError 'points: row 0 ...
    is beyond +-1e+06 mm') for every robot kind; the same number in a --points CSV is named."""
    o = run_argv(argv)
    assert o.code == 2, (o.code, o.stderr[-500:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --grid"), o.stderr
    assert "mm is beyond +-1e+06 mm: not a plausible position" in lines[0]


@pytest.mark.parametrize("value", ["1e300", "1e-300", "2e12"])
def test_a_leg_stiffness_outside_the_files_range_is_an_error_of_param(value):
    """Found by the fuzzing: --param k_leg1=1e300 (or 1e-300) reached the model, whose every pose
    was 'singular: the legs do not hold the platform in every direction' (the TOML's [params]
    refuses the same number, by name)."""
    o = run_argv(["model", "legs", "hexapod", "--grid", "0,0,300", "--param", f"k_leg1={value}"])
    assert o.code == 2, (o.code, o.stderr[-500:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(
        "error: --param: k_leg1: a stiffness between 1e-06 and 1e+12"
    )
    ok = run_argv(["model", "legs", "hexapod", "--grid", "0,0,300", "--param", "k_leg1=1e12", "--json"])
    assert ok.code == 0, ok.stderr  # the range's end is in it


@pytest.mark.parametrize("offset", ["a,b,c", "1;2;3"])
def test_a_tip_offset_that_is_not_numbers_is_named(tmp_path, offset):
    """Found by the fuzzing: --tip-offset-mm a,b,c was an internal error (ValueError: could not
    convert string to float), where 1,2 or nan,0,0 were named."""
    (tmp_path / "q.csv").write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,20,-30,40,50,60\n")
    urdf = str(fr.TEST_ROBOTS / "acme_rs6.urdf")
    argv = [
        "model",
        "urdf",
        urdf,
        "--tip",
        "tool0",
        "--configs",
        str(tmp_path / "q.csv"),
        "--param",
        "k_theta=1e7",
    ]
    o = run_argv([*argv, f"--tip-offset-mm={offset}"])
    assert o.code == 2, (o.code, o.stderr[-500:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert (
        len(lines) == 1
        and f"tip offset must be three finite numbers within 1e+06 mm, got {offset!r}" in lines[0]
    )


@pytest.mark.parametrize(
    ("param", "offset"),
    [("k_theta=1e-300", "1e6,0,0"), ("k_theta=1e-300", "0,0,0"), ("k_theta=1e13", "0,0,0")],
)
def test_a_joint_stiffness_outside_the_range_is_an_error_of_param(tmp_path, param, offset):
    """Found by the fuzzing: k_theta=1e-300 with --tip-offset-mm 1e6,0,0 on the cluttered mobile
    manipulator was an internal error (RuntimeWarning: invalid value encountered in matmul); the
    legs TOML's range 1e-6..1e12 (N*mm/rad or N/mm, or inf) now holds for a URDF's --param too."""
    (tmp_path / "q.csv").write_text(
        "q1_mm,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\n120,10,20,-30,40,50,60\n"
    )
    argv = [
        "model",
        "urdf",
        str(fr.TEST_ROBOTS / "cluttered_mm.urdf"),
        "--base",
        "base_link",
        "--tip",
        "r_tool0",
    ]
    o = run_argv([*argv, "--configs", str(tmp_path / "q.csv"), f"--tip-offset-mm={offset}", "--param", param])
    assert o.code == 2, (o.code, o.stderr[-500:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(
        "error: --param: k1 (torso_lift_joint): a stiffness between 1e-06"
    ), o.stderr
    assert "N/mm" in lines[0]  # the torso lift is prismatic


def test_a_configurations_header_of_a_huge_field_is_named(tmp_path):
    """Found by the long fuzz profile: a header cell of 200 000 characters was an internal error
    (_csv.Error: field larger than field limit) in the configurations reader."""
    q = tmp_path / "q.csv"
    q.write_text("q" + "7" * 200_000 + "_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,20,-30,40,50,60\n")
    urdf = str(fr.TEST_ROBOTS / "acme_rs6.urdf")
    o = run_argv(["model", "urdf", urdf, "--tip", "tool0", "--configs", str(q), "--param", "k_theta=1e7"])
    assert o.code == 2, (o.code, o.stderr[-300:])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "q.csv: line 1: not a table of numbers" in lines[0], o.stderr[-300:]


def test_simulate_of_configurations_at_one_point_names_the_position(tmp_path):
    """Found by the long fuzz profile: a URDF whose chain to the tip is one joint turning the tip
    about its own axis (joint_6's parent link misspelt) puts both configurations at one point;
    simulate --robot was an internal error (ValueError: the robot does not reach ... ambiguous)."""
    _misspelt_parent(tmp_path / "r.urdf", "link_5", "link_6", "link_55")
    (tmp_path / "q.csv").write_text("q1_deg\n10.0\n-80.0\n")
    argv = [
        "simulate",
        str(tmp_path / "out"),
        "--truth-only",
        "--robot",
        str(tmp_path / "r.urdf"),
        "--tip",
        "tool0",
    ]
    o = run_argv([*argv, "--configs", str(tmp_path / "q.csv"), "--param", "k_theta=1e7"])
    assert o.code == 2, (o.code, o.stderr[-500:])
    errors = [ln for ln in o.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: position 1 (80, 0, 0) mm"), o.stderr
    assert "configurations 1 and 2 both put the point here" in errors[0]
