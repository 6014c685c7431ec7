"""A wrong ``--board`` on every real set: the answer's time, against the full failing calibration.

For every real set beside the repository (``../shared/data/calib_example``, Bouguet's 13x12
board; the three cameras of ``../shared/data/real`` and OpenCV's stereo samples'
left camera, ``tests/data/stereo_opencv``, 9x6 boards) ``stiffmap calibrate`` is run in a
subprocess with the board asked too small (two fewer corners each way: a sub-grid), too large
(one more each way: the squares counted), one row short, and swapped (COLS and ROWS exchanged:
the same board, it must pass), each:

- with the check (:func:`stiffmap.vision.board_size.check_board_size`): wall time of the whole
  command (Python start-up and import included) and its answer;
- without it (the baseline: the command as it was, ``check_board_size`` replaced by a no-op in
  the child), for the board too small and too large (a row short is like the latter): the full
  search's wall time (stopped after ``--baseline-timeout`` s, default 150) and what it said.

And the check alone, in this process, when the size is right (its cost on every good run).

Run: .venv/bin/python benchmarks/bench_real_board_size.py [--quick]   (writes results/real_board_size.md)
``--quick`` leaves the baselines out.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _table import save  # noqa: E402
from helpers.shared_data import CALIB_DIR, REAL_SETS  # noqa: E402

from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision.board_size import check_board_size  # noqa: E402
from stiffmap.vision.files import image_files  # noqa: E402

STEREO = HERE.parent / "tests" / "data" / "stereo_opencv"
#: The command as it was: the check replaced by a no-op before the command line runs.
BASELINE = (
    "import sys, stiffmap.vision.files as f; f.check_board_size = lambda *a, **k: []; "
    "from stiffmap.cli.main import run; sys.argv = ['stiffmap', *sys.argv[1:]]; run()"
)


def _sets() -> list[tuple[str, list[Path], tuple[int, int]]]:
    out = [("calib_example (13x12)", image_files([CALIB_DIR]), (13, 12))]
    out += [(f"{name} (9x6)", image_files([d]), (9, 6)) for name, (d, _, _) in REAL_SETS.items()]
    out.append(("stereo left (9x6)", sorted(STEREO.glob("left*.jpg")), (9, 6)))
    return out


def _run(paths: list[Path], size: tuple[int, int], baseline: bool, timeout: float) -> tuple[str, str]:
    """Wall time and the answer (exit status and the error line, cut) of one ``calibrate``."""
    head = [sys.executable, "-c", BASELINE] if baseline else [sys.executable, "-m", "stiffmap"]
    with tempfile.TemporaryDirectory() as tmp:
        args = ["calibrate", *map(str, paths), "--board", f"{size[0]}x{size[1]}", "--square-mm", "25"]
        t0 = time.perf_counter()
        try:
            r = subprocess.run(
                [*head, *args, "--out", f"{tmp}/c.json"], capture_output=True, text=True, timeout=timeout
            )
        except subprocess.TimeoutExpired:
            return f"> {timeout:.0f} s", "(stopped)"
        wall = time.perf_counter() - t0
    err = next((ln for ln in r.stderr.splitlines() if ln.startswith("error:")), "")
    said = err[7:].replace("|", "/")
    said = said if len(said) <= 90 else said[:87] + "..."
    return f"{wall:.1f} s", f"exit {r.returncode}" + (f": {said}" if said else "")


def _check_right(paths: list[Path], size: tuple[int, int]) -> str:
    t0 = time.perf_counter()
    seen = check_board_size(paths, Chessboard(*size, 25.0))
    return f"{1000 * (time.perf_counter() - t0):.0f} ms ({len(seen)} image)"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="leave the baselines out")
    ap.add_argument("--baseline-timeout", type=float, default=150.0)
    opts = ap.parse_args()
    rows = []
    for name, paths, (c, r) in _sets():
        right = _check_right(paths, (c, r))
        cases = {
            "too small": (c - 2, r - 2),
            "squares counted": (c + 1, r + 1),
            "a row short": (c, r - 1),
            "swapped": (r, c),
        }
        for case, size in cases.items():
            wall, said = _run(paths, size, False, 120)
            if opts.quick or case in ("swapped", "a row short"):
                base = ("-", "-")
            else:
                base = _run(paths, size, True, opts.baseline_timeout)
            rows.append([name, f"{case}: {size[0]}x{size[1]}", wall, said, *base, right])
            print(" | ".join(rows[-1]), flush=True)
            right = ""
    save(
        "real_board_size",
        "A wrong --board on the real sets: answered in seconds with the size the images show",
        [
            "set (board)",
            "--board asked",
            "calibrate wall",
            "its answer",
            "before (no check) wall",
            "before: its answer",
            "check alone, right size",
        ],
        rows,
        notes="\n\n".join(__doc__.split("\n\n")[1:4])
        + "\n\nWall times on a shared 2-core machine (other work running): the command's own start-up "
        "(Python, imports) is about 1.5-2 s of each. The swapped size is the same board: it calibrates.",
    )


if __name__ == "__main__":
    main()
