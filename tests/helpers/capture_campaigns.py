"""Small simulated campaigns for the guided-capture tests: the truth and spec, no images yet."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers.board_scenes import scaled_camera
from stiffmap.camera import reference_camera
from stiffmap.campaign.simulated import write_campaign
from stiffmap.loads import load_from_mass
from stiffmap.models.presets import paper48
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import demo_scene
from stiffmap.sim.testbed import SimConfig

#: Fast simulated-camera settings for tests: 5 frames per simulated second, a swing of
#: 1.7 Hz decaying with tau = 0.1 s (the defaults are 10 fps, 2.2 Hz, 0.25 s).
#: The load cases: three axes, and a smaller load that makes the design identify an offset too.
LOADS = ((0.5, "+y"), (0.5, "-x"), (0.5, "-z"), (0.2, "-z"))

FAST_SIM = "sim:fps=5,time_constant_s=0.1,frequency_hz=1.7"

CAPTURE_TOML = """
[capture]
settle_seconds = {settle}
timeout_s = {timeout}
"""


def small_campaign(
    root: Path,
    *,
    positions=(1, 22),
    scale: float = 0.5,
    repeats: int = 1,
    settle: float = 0.6,
    timeout: float = 30.0,
    extra: str = "",
) -> Path:
    """A simulated campaign (demo scene seen by a camera ``scale`` times the reference's size, the
    Delta robot at some ``paper48`` positions, the :data:`LOADS`; the robot stays at each
    position) with its truth and spec but no images, and a ``[capture]`` section."""
    cfg = SimConfig(
        scene=demo_scene(scaled_camera(reference_camera(), scale)),
        robot=delta_robot(),
        positions=paper48()[np.asarray(positions) - 1],
        loads=tuple(load_from_mass(m, d, g=9.81) for m, d in LOADS),
        repeats=repeats,
        seed=3,
        robot_stays=True,
        calibration_views=0,
        name="capture test",
    )
    write_campaign(root, cfg, render_images=False, command="capture test campaign")
    with open(root / "campaign.toml", "a", encoding="utf-8") as f:
        f.write(CAPTURE_TOML.format(settle=settle, timeout=timeout) + extra)
    return root
