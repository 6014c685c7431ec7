"""Write ``legs_before_links.json``: the leg robots' numbers before flexible links in legs.

Run once on main at 8a1e20e (before ``[[legs.links]]``), e.g. from an export of that commit:
``git archive 8a1e20e src | tar -x -C /tmp/old && PYTHONPATH=/tmp/old/src .venv/bin/python
tests/data/make_legs_before_links.py``. ``test_models_legs_links.py`` checks that the Delta,
the 3PRR, the hexapod and the 3-RPS read from their legs TOML (no links) still give these
numbers to 1e-12.
"""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import numpy as np

from stiffmap.models.legs import LegRobot

ROBOTS = files("stiffmap.models") / "robots"


def _poses(rng, centre, spread_mm, spread_deg, n):
    P = np.zeros((n, 6))
    P[:, :3] = np.asarray(centre) + rng.uniform(-spread_mm, spread_mm, size=(n, 3))
    P[:, 3:] = np.radians(rng.uniform(-spread_deg, spread_deg, size=(n, 3)))
    return P


def _record(model, P):
    m = model.evaluate(P)
    out = {"points": P.tolist(), "valid": m.valid.tolist(), "K": np.nan_to_num(m.K).tolist()}
    if m.K6 is not None:
        out["K6"] = np.nan_to_num(m.K6).tolist()
    return out


def main() -> None:
    rng = np.random.default_rng(2929)
    rps = np.zeros((6, 6))
    rps[:, 2] = np.linspace(220.0, 290.0, 6)  # the 3-RPS, level: x, y, yaw follow from z, roll, pitch
    out = {
        "commit": "8a1e20e",
        "delta": _record(
            LegRobot.from_toml(ROBOTS / "delta.toml"), rng.uniform(-120, 120, (6, 3)) - [0, 0, 300]
        ),
        "3prr": _record(LegRobot.from_toml(ROBOTS / "3prr.toml"), rng.uniform(300, 500, (6, 2))),
        "hexapod": _record(LegRobot.from_toml(ROBOTS / "hexapod.toml"), _poses(rng, (0, 0, 300), 30, 8, 6)),
        "3rps": _record(LegRobot.from_toml(ROBOTS / "3rps.toml"), rps),
    }
    path = Path(__file__).with_name("legs_before_links.json")
    path.write_text(json.dumps(out) + "\n", encoding="utf-8")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
