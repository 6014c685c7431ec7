"""``compensate --place auto`` on the six-joint arm and a long program that fits its reach.

The program (written here): ``SQUARES`` stacked 200 mm squares (G1, one every 0.5 mm in z,
a G0 to the start), 80 m of feed for 100 squares; the arm ``urdf arm6`` with its default tool,
seed and a force turning with the feed (FT 20, FN 15, FZ 10 N), as in
``bench_gcode_sweep.py``. Printed and saved (``benchmarks/results/place_arm.md``) for each
count of squares: the wall time of :func:`place_program` (the search alone, one process),
the placement, its worst deflection, and the placements evaluated.

Run:  nice .venv/bin/python benchmarks/bench_place_arm.py [SQUARES ...]   (default 1 3 100)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _table import save  # noqa: E402

from stiffmap.machining.field import field_for  # noqa: E402
from stiffmap.machining.forces import ForceSpec  # noqa: E402
from stiffmap.machining.io import read_program  # noqa: E402
from stiffmap.machining.path import toolpath_from_moves  # noqa: E402
from stiffmap.machining.place import place_program  # noqa: E402
from stiffmap.models import arm6  # noqa: E402


def stacked_squares(n: int, side: float = 200.0, dz: float = 0.5) -> str:
    """``n`` squares of ``side`` mm, one above the other ``dz`` mm apart, cut in G1."""
    lines = ["G21 G90 G17", "G0 X0 Y0 Z5", "G1 Z0 F600"]
    for i in range(n):
        z = i * dz
        lines += [f"G1 Z{z:.3f}", f"G1 X{side:g}", f"G1 Y{side:g}", "G1 X0", "G1 Y0"]
    lines += ["G0 Z60", "M2"]
    return "\n".join(lines) + "\n"


def run(n: int) -> list:
    """One row: squares, feed (m), seconds, placement (mm), worst deflection (um), placements."""
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
    place = ", ".join(f"{v:.3f}" for v in found.place)
    row = [n, f"{feed_m:.1f}", f"{took:.1f}", f"({place})", f"{found.value * 1e3:.3f}", found.evaluations]
    print(row, flush=True)
    return row


def main(counts) -> None:
    rows = [run(n) for n in counts]
    save(
        "place_arm",
        "compensate --place auto: the six-joint arm on stacked 200 mm squares",
        ["squares", "feed (m)", "search (s)", "placement (mm)", "worst deflection (um)", "placements"],
        rows,
        notes=__doc__.split("Run:")[0],
    )


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1, 3, 100])
