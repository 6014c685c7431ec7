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
