"""Compensated programs, deflected by independent solvers, lie on the programmed path.

Programs: public ones nobody on the project wrote (cncjs's test fixtures and visualizer
fixture, MIT; tests/data/gcode/README.md) and two of ours (an inch program of R-format arcs
without spaces in every plane, a CAM-style program with line numbers, a ramp, G91 and G28).
Each is compensated by ``compensate_file`` for a model, written, read back, sampled along
every feed move of the output (two points per mm, at least nine per move) and deflected by a
solver written in ``tests/helpers/machining_checks.py``, not the code under test:

- the milling study's 3PRR (kj 525 N/mm, kb 9 800 N/mm, rods of E A = 7e6 N; its Section 4)
  under its 50 kgf load (490.5 N with the study's g = 9.81), by a direct-stiffness truss;
- the six-joint test arm, by C = J K^-1 J^T with a central-difference Jacobian;
- the Delta, by K = k_theta J^T J with J = dtheta/dP by central differences.

Every deflected sample must lie within the tolerance asked (2 um) of the programmed path, and
every point of the programmed feed moves must have a deflected sample within the tolerance
plus half the sampling step (the output covers the whole path). (A program's first move starts
wherever the machine stands: a feed there is an approach, not a cut, in the input and in the
output alike: ``toolpath_from_moves``.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers.machining_checks import (
    arm_deflection,
    delta_deflection,
    distance_to_path,
    output_samples,
    truss_3prr,
)

from stiffmap.machining import CompensateOptions, ForceSpec, compensate_file
from stiffmap.machining.io import read_program
from stiffmap.machining.path import toolpath_from_moves
from stiffmap.models import arm6
from stiffmap.models.delta import DeltaRobot
from stiffmap.models.prr3 import PRR3

DATA = Path(__file__).parent / "data" / "gcode"
TOL_UM = 2.0
#: The milling study's 3PRR: kj, kb published; rods of E A = 7e6 N (E 70 000 MPa x 100 mm^2).
PRR3_STUDY = {"h": 800.0, "L": 250.0, "E": 70000.0, "area": 100.0, "kj": 525.0, "kb": 9800.0}
LOAD_50_KGF_N = 50 * 9.81
PER_MM = 2.0

PROGRAMS = [
    "cncjs_circle-inch.gcode",
    "cncjs_toolpath.nc",
    "cncjs_arc-xz-plane.nc",
    "cncjs_arc-yz-plane.nc",
    "cncjs_circle.nc",
    "own_inch_r_planes.nc",
    "own_cam_mm.nc",
    "cncjs_linear.nc",
]


def _compensated(tmp_path, mechanism, name, place, force):
    out = tmp_path / ("out_" + name)
    opts = CompensateOptions(tolerance_um=TOL_UM, place_mm=place, force=ForceSpec.constant(force))
    res = compensate_file(mechanism, DATA / name, out, opts)
    prog, _ = read_program(DATA / name)
    done, _ = read_program(out)
    return res, toolpath_from_moves(prog.moves), toolpath_from_moves(done.moves)


def _check(programmed, deflected, step_mm):
    far = distance_to_path(programmed, deflected)
    assert np.max(far) <= TOL_UM * 1e-3 + 1e-9, (
        f"a deflected point is {1e3 * np.max(far):.3f} um off the path"
    )
    _, _, P = output_samples(programmed, per_mm=PER_MM)
    gap = np.min(np.linalg.norm(P[:, None, :] - deflected[None, :, :], axis=2), axis=1)
    assert np.max(gap) <= TOL_UM * 1e-3 + step_mm / 2 + 1e-6, "the output misses part of the programmed path"


@pytest.mark.parametrize("name", PROGRAMS)
def test_3prr_programs_deflect_onto_the_programmed_path(tmp_path, name):
    model = PRR3(**PRR3_STUDY)
    force = np.array([0.0, -LOAD_50_KGF_N, 0.0]) if "inch" in name else np.array([LOAD_50_KGF_N, 0.0, 0.0])
    res, prog_path, out_path = _compensated(tmp_path, model, name, (380.0, 200.0, 0.0), force)
    _, _, C = output_samples(out_path, per_mm=PER_MM)
    d = truss_3prr(
        (C[:, :2] + [380.0, 200.0]), force[:2], EA=7e6, **{k: PRR3_STUDY[k] for k in ("h", "L", "kj", "kb")}
    )
    D = C.copy()
    D[:, :2] += d
    _check(prog_path, D, 1 / PER_MM)
    # the compensation did something worth checking: deflections of tenths of a millimetre
    assert res.summary["deflection_before_um"]["worst"] > 100.0
    assert res.summary["residual_after_um"]["worst"] <= TOL_UM


@pytest.mark.parametrize("name", ["cncjs_toolpath.nc", "own_cam_mm.nc"])
def test_arm6_programs_deflect_onto_the_programmed_path(tmp_path, name):
    robot = arm6.model()
    place = np.array([480.0, -30.0, 380.0])
    force = np.array([20.0, -15.0, 10.0])
    res, prog_path, out_path = _compensated(tmp_path, robot, name, place, force)
    _, _, C = output_samples(out_path, per_mm=PER_MM)
    d, _ = arm_deflection(
        robot.chain,
        arm6.K_THETA,
        arm6.TOOL_ROTATION,
        C + place,
        np.tile(force, (C.shape[0], 1)),
        np.radians(arm6.Q_SEED_DEG),
    )
    _check(prog_path, C + d, 1 / PER_MM)
    assert res.summary["deflection_before_um"]["worst"] > 100.0


def test_arm6_cuts_on_the_branch_the_program_reaches_them_on(tmp_path):
    # Placed where --place auto puts own_cam_mm.nc (20, -15, 10 N): the cut's first point solved
    # from the seed alone (skipping the rapids to it) puts joint_3 at 155.5 deg, beyond its limit
    # of 50 deg; the arm that follows the program from the seed, rapids included, reaches it at
    # 39.5 deg. The compensation once refused the program there ("line 15: programmed point ...
    # unreachable: joint joint_3 at 155.536 deg"), so --place auto chose a placement it then
    # refused. Checked: the arm walked (arm_deflection, in order from the seed) through the
    # program's points before the first cut stays within the joint limits, and from there the
    # output deflects onto the path.
    robot = arm6.model()
    place = np.array([0.0, 230.58305695, 462.36989469])
    force = np.array([20.0, -15.0, 10.0])
    res, prog_path, out_path = _compensated(tmp_path, robot, "own_cam_mm.nc", place, force)
    first = int(np.argmax(prog_path.feed))
    lead_in = [prog_path.start[i] for i in range(first) if np.all(prog_path.known_start[i])]
    lead_in = np.array(lead_in + [prog_path.start[first]]) + place  # every move's start, the cut's last
    walk = dict(chain=robot.chain, k_theta=arm6.K_THETA, rotation=arm6.TOOL_ROTATION)
    _, q = arm_deflection(
        **walk, points=lead_in, forces=np.zeros_like(lead_in), q0=np.radians(arm6.Q_SEED_DEG)
    )
    assert np.all((q >= robot.chain.lower) & (q <= robot.chain.upper)), np.degrees(q)
    _, q_seed_only = arm_deflection(**walk, points=prog_path.start[first][None] + place,
                                    forces=np.zeros((1, 3)), q0=np.radians(arm6.Q_SEED_DEG))  # fmt: skip
    assert q_seed_only[2] > robot.chain.upper[2]  # the branch the seed alone gives: joint_3 beyond
    _, _, C = output_samples(out_path, per_mm=PER_MM)
    d, _ = arm_deflection(**walk, points=C + place, forces=np.tile(force, (C.shape[0], 1)), q0=q)
    _check(prog_path, C + d, 1 / PER_MM)
    assert res.summary["deflection_before_um"]["worst"] > 100.0


@pytest.mark.parametrize("name", ["cncjs_toolpath.nc", "own_inch_r_planes.nc"])
def test_delta_programs_deflect_onto_the_programmed_path(tmp_path, name):
    robot = DeltaRobot()
    place = np.array([-40.0, -30.0, -300.0])
    force = np.array([4.0, 3.0, -2.0])
    res, prog_path, out_path = _compensated(tmp_path, robot, name, place, force)
    _, _, C = output_samples(out_path, per_mm=PER_MM)
    d = delta_deflection(robot, C + place, np.tile(force, (C.shape[0], 1)))
    _check(prog_path, C + d, 1 / PER_MM)
    assert res.summary["deflection_before_um"]["worst"] > 100.0


#: Two squares cut in G91, in the style of a hand-written teaching program (``G00;`` alone, a
#: retract naming only Z between the shapes): the rapid to the second shape takes its increments
#: from where the compensated first shape left the tool, not from the programmed point.
G91_SHAPES = (
    "G21 G90 G17;\nG00;\nX0. Y0. Z0.;\nG91;\nZ5.;\nX20. Y30.;\nG01 F300.;\nZ-6.;\n"
    "X10.;\nY-10.;\nX-10.;\nY10.;\nZ6. G00;\nX25.;\nG01 Z-6.;\nX10. Y-10.;\nX-10. Y-10.;\nX-10. Y10.;\n"
    "X10. Y10.;\nZ6. G00;\nG28;\nM30\n"
)


def test_3prr_incremental_program_between_shapes(tmp_path):
    (tmp_path / "g91.nc").write_text(G91_SHAPES)
    model = PRR3(**PRR3_STUDY)
    force = np.array([0.0, -LOAD_50_KGF_N, 0.0])
    out = tmp_path / "out.nc"
    opts = CompensateOptions(
        tolerance_um=TOL_UM, place_mm=(380.0, 200.0, 0.0), force=ForceSpec.constant(force)
    )
    res = compensate_file(model, tmp_path / "g91.nc", out, opts)
    prog, _ = read_program(tmp_path / "g91.nc")
    done, _ = read_program(out)
    out_path = toolpath_from_moves(done.moves)
    _, _, C = output_samples(out_path, per_mm=PER_MM)
    d = truss_3prr(
        (C[:, :2] + [380.0, 200.0]), force[:2], EA=7e6, **{k: PRR3_STUDY[k] for k in ("h", "L", "kj", "kb")}
    )
    D = C.copy()
    D[:, :2] += d
    _check(toolpath_from_moves(prog.moves), D, 1 / PER_MM)
    assert res.summary["deflection_before_um"]["worst"] > 100.0
    # the retract between the shapes names only Z: written as it was
    assert done.lines[12] == "Z6. G00;" and done.lines[2] == "X0. Y0. Z0.;"
