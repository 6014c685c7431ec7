"""``--place auto`` on the milling study's 3PRR: the minimum of a brute-force grid of placements.

The brute force is written here: every placement of a 20 mm grid over the region where the
program fits in the 3PRR's triangle, the deflection at the program's points by the
direct-stiffness truss of ``helpers.machining_checks`` (not the code under test), a
placement feasible when every programmed point and its compensated point ``p - delta`` are
evaluable by the model with a conditioning of at least ``MIN_CONDITIONING`` (the search's
documented rule). The search's worst deflection must be within 1 % of the grid's minimum
(it refines below the grid's step, so it is usually lower), and its reported value must be
the truss's worst deflection at its placement.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from helpers.machining_checks import truss_3prr

from stiffmap.machining.field import field_for
from stiffmap.machining.forces import ForceSpec
from stiffmap.machining.io import read_program
from stiffmap.machining.path import toolpath_from_moves
from stiffmap.machining.place import MIN_CONDITIONING, default_region, place_program, program_samples
from stiffmap.models.prr3 import PRR3

DATA = Path(__file__).parent / "data" / "gcode"
STUDY = {"h": 800.0, "L": 250.0, "E": 70000.0, "area": 100.0, "kj": 525.0, "kb": 9800.0}


def _truss(P, F):
    return truss_3prr(P, F, h=800.0, L=250.0, EA=7e6, kj=525.0, kb=9800.0)


def test_place_auto_is_the_brute_force_minimum():
    model = PRR3(**STUDY)
    prog, _ = read_program(DATA / "own_cam_mm.nc")
    path = toolpath_from_moves(prog.moves)
    forces = ForceSpec.constant((0.0, -50 * 9.81))
    found = place_program(field_for(model), path, forces, objective="worst")

    P, F, feed = program_samples(path, forces)
    lo, hi = default_region(model)
    xs = np.arange(lo[0] - P[:, 0].min(), hi[0] - P[:, 0].max(), 20.0)
    ys = np.arange(lo[1] - P[:, 1].min(), hi[1] - P[:, 1].max(), 20.0)
    T = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    n = P.shape[0]
    Q = (P[None, :, :2] + T[:, None]).reshape(-1, 2)
    ok = _evaluable(model, Q).reshape(-1, n).all(axis=1)
    Fq = np.tile(F[:, :2], (T.shape[0], 1))
    d = np.full((Q.shape[0], 2), np.nan)
    rows = np.repeat(ok, n)
    d[rows] = _truss(Q[rows], Fq[rows])
    ok[ok] = _evaluable(model, (Q - np.nan_to_num(d))[rows]).reshape(-1, n).all(axis=1)
    worst = np.linalg.norm(d, axis=1).reshape(-1, n)[:, feed].max(axis=1)
    brute = np.min(np.where(ok, worst, np.inf))
    assert np.isfinite(brute) and ok.sum() > 50

    ours = np.linalg.norm(_truss(P[:, :2] + found.place[:2], F[:, :2])[feed], axis=1).max()
    assert found.value == np.float64(found.value) and abs(found.value - ours) <= 1e-9 + 1e-6 * ours
    assert ours <= 1.01 * brute, f"search {ours:.6f} mm, brute-force grid {brute:.6f} mm"


def _evaluable(model, Q):
    m = model.evaluate(Q)
    return m.valid & (np.nan_to_num(m.conditioning, nan=-1.0) >= MIN_CONDITIONING)
