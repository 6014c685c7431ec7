"""A serial arm's stiffness map from its URDF: K at the measured point over a box of positions.

The arm is stiffmap's six-joint test arm (``arm6``, shipped with the package; give another
URDF with ``--urdf FILE --tip FRAME``), with a spring at every joint, k1 .. k6 (N*mm/rad).
Each position is reached by inverse kinematics with the tool pointing down; the map prints
the principal stiffnesses (N/mm) there and where the arm is softest.

    python examples/urdf_arm_map.py
    python examples/urdf_arm_map.py --grid 400:650:6,-150:150:7,400 --k 2e7,1.6e7,1.2e7,5e6,4e6,3e6
"""

from __future__ import annotations

import argparse

import numpy as np

from stiffmap.kinds import grid_from_text, robot_from_options
from stiffmap.models import arm6


def main(argv: list[str] | None = None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--urdf", default="arm6", help="a URDF file, or arm6 (stiffmap's test arm)")
    p.add_argument("--tip", default=arm6.TIP_FRAME, help="the link carrying the measured point")
    p.add_argument("--tip-offset-mm", default="0,0,100", help="the measured point in that link, mm")
    p.add_argument("--k", default=",".join(f"{k:g}" for k in arm6.K_THETA), help="k1,...,kn (N*mm/rad)")
    p.add_argument("--grid", default="arm20", help="arm20 (default) or X0:X1:NX,Y0:Y1:NY,Z0:Z1:NZ (mm)")
    a = p.parse_args(argv)
    ks = [f"k{i}={v}" for i, v in enumerate(a.k.split(","), start=1)]
    offset = tuple(float(v) for v in a.tip_offset_mm.split(","))
    robot = robot_from_options(
        "urdf",
        a.urdf,
        params=ks,
        tip_frame=a.tip,
        tip_offset_mm=offset,
        tool_rpy_deg=(0.0, 180.0, 0.0),  # the tool pointing down (a half turn about y)
        q_seed_deg=arm6.Q_SEED_DEG,
    )
    P = grid_from_text(a.grid, "urdf")
    m = robot.evaluate(P)
    print(robot.describe())
    print(f"{m.n_valid} of {len(m)} positions reached")
    for p_, ev, ok, why in zip(m.points, m.eigenvalues, m.valid, m.reasons, strict=True):
        where = ", ".join(f"{v:7.1f}" for v in p_)
        print(f"({where}) mm: " + (", ".join(f"{v:8.1f}" for v in ev) + " N/mm" if ok else why))
    if m.n_valid:
        i = int(np.nanargmin(np.where(m.valid, m.min_principal, np.nan)))
        print(f"softest at {m.points[i].tolist()} mm: {m.min_principal[i]:.1f} N/mm")
    return m


if __name__ == "__main__":
    main()
