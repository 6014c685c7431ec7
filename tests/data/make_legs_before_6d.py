"""Write ``legs_before_6d.json``: the 2-D and 3-D leg robots' numbers before the 6-D assembly.

Run once on main at e83d1d9 (before issue 30's 6-DOF legs):
``.venv/bin/python tests/data/make_legs_before_6d.py``. ``test_models_legs6.py`` checks that the
Delta and the 3PRR (built-in and from their legs TOML) still give these numbers to 1e-12.
"""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import numpy as np

from stiffmap.models import PRR3, DeltaRobot
from stiffmap.models.legs import LegRobot

ROBOTS = files("stiffmap.models") / "robots"


def _grid(lo, hi, n):
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))


def _record(model, P):
    m = model.evaluate(P)
    s, p = model.singularity_measures(P)
    return {
        "points": P.tolist(),
        "valid": m.valid.tolist(),
        "K": np.where(np.isnan(m.K), 0.0, m.K).tolist(),
        "q": np.where(np.isnan(m.q), 0.0, m.q).tolist(),
        "serial": np.where(np.isnan(s), -1.0, s).tolist(),
        "parallel": np.where(np.isnan(p), -1.0, p).tolist(),
    }


def main() -> None:
    delta_pts = _grid((-150.0, -150.0, -380.0), (150.0, 150.0, -220.0), 3)
    prr3_pts = _grid((250.0, 100.0), (550.0, 400.0), 4)
    out = {
        "commit": "e83d1d9",
        "delta_builtin": _record(DeltaRobot(), delta_pts),
        "delta_legs": _record(LegRobot.from_toml(ROBOTS / "delta.toml"), delta_pts),
        "prr3_builtin": _record(PRR3(), prr3_pts),
        "prr3_legs": _record(LegRobot.from_toml(ROBOTS / "3prr.toml"), prr3_pts),
    }
    path = Path(__file__).with_name("legs_before_6d.json")
    path.write_text(json.dumps(out) + "\n", encoding="utf-8")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
