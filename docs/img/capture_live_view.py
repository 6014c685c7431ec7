"""Render the live view of ``stiffmap capture`` to docs/img/capture-live-view.svg.

A real moment of a capture: the demo's scene seen by the simulated camera, at position 12 of
``paper48`` position, 0.3 s after 0.5 kg was hung on the +Y pulley (the platform still swings).
Run: ``python docs/img/capture_live_view.py``.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from stiffmap.capture.session import ViewState
from stiffmap.capture.settle import SettleMonitor
from stiffmap.capture.view import render_view
from stiffmap.loads import paper9
from stiffmap.models.presets import paper48
from stiffmap.sim.live_camera import SimulatedCamera
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import demo_scene

scene = demo_scene()
cam = SimulatedCamera(scene, delta_robot(), seed=1)
monitor = SettleMonitor(scene.camera, scene.mobile_board, scene.fixed_board, scene.fixed2base)
with cam:
    cam.move_to(paper48()[11])
    for _ in range(12):
        cam.grab()
    cam.set_load(paper9()[0].force)
    for _ in range(8):
        f = cam.grab()
        check = monitor.check(f.image, f.timestamp_s)
state = ViewState(
    campaign="my delta robot, 2026-11",
    step=112,
    steps=480,
    image="images/p12/l01_r01_loaded.png",
    on_disk=111,
    instruction="hang 0.500 kg on the +Y pulley  (loaded image, load 1, repeat 1)",
    check=check,
    collected=0,
    needed=1,
    settle_seconds=1.0,
    status=check.problem or "waiting for the platform to settle",
    saved=["images/p12/r01_unloaded.png"],
)
console = Console(record=True, width=100, force_terminal=True)
console.print(render_view(state))
out = Path(__file__).with_name("capture-live-view.svg")
console.save_svg(str(out), title="stiffmap capture")
print(f"wrote {out}")
