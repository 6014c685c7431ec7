"""Identify a stiffness matrix K from load cases and measured displacements in CSV files.

As ``stiffmap identify FORCES.csv DISPLACEMENTS.csv`` does: each row of the forces file is a
load case (fx, fy, fz in N), the same row of the displacements file what it moved the tool
by (dx, dy, dz in mm); K (N/mm) is the least-squares fit of d = K^-1 F, with standard
errors, its principal stiffnesses and the checks a measured K should pass.

    python examples/identify_from_csv.py forces.csv displacements.csv
    python examples/identify_from_csv.py --demo      # writes both files from a known K first
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from stiffmap.campaign.identify_files import identify_from_files
from stiffmap.loads import forces_matrix, paper9


def write_demo_files(folder: Path, seed: int = 0) -> tuple[Path, Path, np.ndarray]:
    """Forces of the reference study's nine load cases and displacements of a known K with noise."""
    K = np.array([[60.0, 4.0, -2.0], [4.0, 45.0, 3.0], [-2.0, 3.0, 200.0]])  # N/mm
    F = forces_matrix(paper9()).T  # N, one row per load case
    rng = np.random.default_rng(seed)
    D = np.linalg.solve(K, F.T).T + rng.normal(scale=2e-4, size=F.shape)  # mm, 0.2 um noise
    f, d = folder / "forces.csv", folder / "displacements.csv"
    f.write_text("fx,fy,fz\n" + "".join(",".join(f"{v!r}" for v in r) + "\n" for r in F.tolist()))
    d.write_text("dx,dy,dz\n" + "".join(",".join(f"{v!r}" for v in r) + "\n" for r in D.tolist()))
    return f, d, K


def main(argv: list[str] | None = None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("forces", type=Path, nargs="?", help="CSV with columns fx, fy, fz (N)")
    p.add_argument("displacements", type=Path, nargs="?", help="CSV with columns dx, dy, dz (mm)")
    p.add_argument("--demo", action="store_true", help="write the two files from a known K first")
    a = p.parse_args(argv)
    if a.demo:
        a.forces, a.displacements, K_true = write_demo_files(Path(tempfile.mkdtemp()))
        print("true K (N/mm):\n", K_true)
    res = identify_from_files(a.forces, a.displacements)
    fit = res.fit
    with np.printoptions(precision=3, suppress=True):
        print("K (N/mm):\n", fit.K)
        print("1-sigma (N/mm):\n", fit.K_std)
        print("principal stiffnesses (N/mm):", fit.indices.eigenvalues)
    print("flags:", list(fit.flags) or "none")
    return res


if __name__ == "__main__":
    main()
