"""``compensate --place auto`` on the six-joint arm and a long program that fits its reach.

The program (written here): ``SQUARES`` stacked 200 mm squares (G1, one every 0.5 mm in z,
a G0 to the start), 80 m of feed for 100 squares; the arm ``urdf arm6`` with its default tool,
seed and a force turning with the feed (FT 20, FN 15, FZ 10 N), as in
``bench_gcode_sweep.py``. Printed: the wall time of :func:`place_program` (the search alone,
one process), the placement, its worst deflection, and the placements evaluated.

Run:  nice .venv/bin/python benchmarks/bench_place_arm.py [SQUARES]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from stiffmap.machining.field import field_for
from stiffmap.machining.forces import ForceSpec
from stiffmap.machining.io import read_program
from stiffmap.machining.path import toolpath_from_moves
from stiffmap.machining.place import place_program
from stiffmap.models import arm6


def stacked_squares(n: int, side: float = 200.0, dz: float = 0.5) -> str:
    """``n`` squares of ``side`` mm, one above the other ``dz`` mm apart, cut in G1."""
    lines = ["G21 G90 G17", "G0 X0 Y0 Z5", "G1 Z0 F600"]
    for i in range(n):
        z = i * dz
        lines += [f"G1 Z{z:.3f}", f"G1 X{side:g}", f"G1 Y{side:g}", "G1 X0", "G1 Y0"]
    lines += ["G0 Z60", "M2"]
    return "\n".join(lines) + "\n"


def main(n: int = 100) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "squares.nc"
        f.write_text(stacked_squares(n))
        prog, _ = read_program(f)
    path = toolpath_from_moves(prog.moves)
    forces = ForceSpec.feed_frame((20.0, 15.0, 10.0))
    fld = field_for(arm6.model())
    t0 = time.perf_counter()
    found = place_program(fld, path, forces)
    took = time.perf_counter() - t0
    feed_m = float(np.sum(np.where(path.feed, path.length(), 0.0))) / 1e3
    print(
        f"{n} stacked 200 mm squares ({feed_m:.1f} m of feed), arm6: --place auto {took:.1f} s, "
        f"place {np.round(found.place, 3).tolist()} mm, worst {found.value * 1e3:.3f} um, "
        f"{found.evaluations} placements evaluated"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
