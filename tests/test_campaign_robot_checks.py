"""The whole [robot] section checked before any image is measured; robot files stay in the campaign
(issue 27: late refusals, someone else's files, a spec whose robot changed after the run).

Before: a missing, escaping or bad URDF or legs file, an unknown ``tip_frame``, ``params`` with
``k7`` or ``fit = ["k9"]`` were found only after every image was measured (exit 1, a "robot
model:" warning), where docs/campaigns.md promises a spec error before anything (exit 2); a
URDF or legs file by absolute path or through a symbolic link out of the campaign was read
without ``--allow-outside-paths``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from helpers.fuzz import run_argv
from helpers.fuzz_campaign import RUN, bare_vision_seed
from helpers.fuzz_safety import measured_seed

from stiffmap.kinds import robot_kind
from stiffmap.models.legs import LegRobot

ROBOTS = Path(__file__).resolve().parents[1] / "src" / "stiffmap" / "models" / "robots"
JOINTS = "params = {k1 = 1e6, k2 = 1e6, k3 = 1e6, k4 = 1e6, k5 = 1e6, k6 = 1e6}"


def _campaign(root: Path, robot: str, files: dict[str, bytes] | None = None) -> Path:
    for name, data in (files or bare_vision_seed()).items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    spec = root / "campaign.toml"
    text = re.sub(r"\[robot\]\n(?:.*\n)*?(?=\n\[)", "[robot]\n" + robot + "\n", spec.read_text(), count=1)
    spec.write_text(text)
    return root


def _arm(root: Path) -> None:
    (root / "robot.urdf").write_bytes((ROBOTS / "arm6.urdf").read_bytes())


def _legs(root: Path) -> None:
    (root / "robot.toml").write_bytes((ROBOTS / "delta.toml").read_bytes())


CASES = {
    "URDF missing": (
        'model = "urdf"\nurdf = "nope.urdf"\ntip_frame = "tool0"',
        None,
        "nope.urdf: no such file",
    ),
    "URDF not XML": (
        'model = "urdf"\nurdf = "robot.urdf"\ntip_frame = "tool0"',
        lambda r: (r / "robot.urdf").write_text("<robot"),
        "robot.urdf: not a valid XML file",
    ),
    "unknown tip_frame": (
        f'model = "urdf"\nurdf = "robot.urdf"\ntip_frame = "nope"\n{JOINTS}',
        _arm,
        "robot.urdf: no frame 'nope' for the measured point",
    ),
    "params k7": (
        'model = "urdf"\nurdf = "robot.urdf"\ntip_frame = "tool0"\nparams = {k7 = 1.0}',
        _arm,
        "robot.params: unknown urdf parameter 'k7'",
    ),
    "fit k9": (
        f'model = "urdf"\nurdf = "robot.urdf"\ntip_frame = "tool0"\n{JOINTS}\nfit = ["k9"]',
        _arm,
        "robot.fit: unknown urdf parameter(s) k9",
    ),
    "URDF by absolute path": (
        f'model = "urdf"\nurdf = "{ROBOTS / "arm6.urdf"}"\ntip_frame = "tool0"\n{JOINTS}',
        None,
        "key 'robot.urdf': '/",
    ),
    "URDF through a link out": (
        f'model = "urdf"\nurdf = "robot.urdf"\ntip_frame = "tool0"\n{JOINTS}',
        lambda r: (r / "robot.urdf").symlink_to(ROBOTS / "arm6.urdf"),
        "key 'robot.urdf': 'robot.urdf' leads through a symbolic link to",
    ),
    "legs missing": ('model = "legs"\nlegs = "nope.toml"', None, "nope.toml: no such file"),
    "legs not TOML": (
        'model = "legs"\nlegs = "robot.toml"',
        lambda r: (r / "robot.toml").write_text("x = ["),
        "robot.toml: not valid TOML",
    ),
    "legs up with ..": (
        'model = "legs"\nlegs = "../robot.toml"',
        None,
        "key 'robot.legs': '../robot.toml' goes up",
    ),
    "fit of a rigid element": (
        'model = "legs"\nlegs = "robot.toml"\nfit = ["k_arm"]',
        _legs,
        "key 'robot.fit': cannot fit k_arm: its starting value inf",
    ),
}


@pytest.mark.parametrize("name", list(CASES))
def test_a_wrong_robot_is_refused_before_any_image_is_measured(tmp_path, name):
    robot, make, needle = CASES[name]
    root = _campaign(tmp_path / "c", robot)
    if make is not None:
        make(root)
    if name == "legs up with ..":
        _legs(tmp_path)
    o = run_argv(["run", str(root), "--quiet", "--no-report", "--workers", "1"])
    (line,) = o.stderr.splitlines()
    assert o.code == 2 and line.startswith("error: ") and needle in line, o.stderr
    assert "allow-outside-paths" in line or "outside" not in line
    # Nothing measured, nothing written.
    assert not (root / "stiffmap.db").exists() and not (root / "exports").exists()


def test_the_default_fit_leaves_rigid_elements_out():
    """The shipped delta.toml holds k_arm = k_forearm = inf: its default fit is k_theta alone
    (before: 'cannot fit k_arm: its starting value inf')."""
    model = LegRobot.from_toml(ROBOTS / "delta.toml")
    assert model.params()["k_arm"] == float("inf")
    assert robot_kind("legs").fitted_names(model) == ("k_theta",)


@pytest.mark.slow
def test_a_robot_file_outside_is_read_with_allow_outside_paths(tmp_path):
    root = _campaign(tmp_path / "c", 'model = "legs"\nlegs = "robot.toml"')
    (root / "robot.toml").symlink_to(ROBOTS / "delta.toml")
    o = run_argv([*(a.replace("{dir}", str(root)) for a in RUN), "--allow-outside-paths", "--json"])
    assert o.code == 0, o.stderr[-1500:]
    (fit,) = json.loads(o.stdout)["model_fits"]
    assert fit["status"] == "ok" and set(fit["params"]) == {"k_theta"}


def test_a_robot_changed_after_the_run_is_said_and_left_out_of_the_report(tmp_path):
    root = _campaign(tmp_path / "c", 'model = "3prr"', files=measured_seed("vision"))
    # truth.json through a link out of the campaign: left out, with a warning.
    (root / "truth.json").rename(tmp_path / "truth.json")
    (root / "truth.json").symlink_to(tmp_path / "truth.json")
    o = run_argv(["report", str(root), "--no-png"])
    assert o.code == 1, o.stderr  # done, with warnings
    robot, truth = [ln for ln in o.stderr.splitlines() if ln.startswith("warning:")]
    assert "stiffmap.db holds the fit of robot model 'delta', but campaign.toml now names '3prr'" in robot
    assert truth.startswith("warning: truth.json leads through a symbolic link to")
    assert "left out of the report (give --allow-outside-paths to read it)" in truth
    data = json.loads((root / "report" / "data.json").read_text())
    assert data["model"] is None and data["truth"] is None and data["measured"] is not None
    assert any("holds the fit of robot model 'delta'" in json.dumps(f) for f in data["failures"])


@pytest.mark.parametrize("command", ["run", "report"])
def test_a_results_database_linked_out_of_the_campaign_is_refused(tmp_path, command):
    """stiffmap.db as a link to another folder's database: a run would write into it."""
    root = _campaign(tmp_path / "c", 'model = "delta"')
    (tmp_path / "other.db").write_bytes(b"another folder's results")
    (root / "stiffmap.db").symlink_to(tmp_path / "other.db")
    o = run_argv([command, str(root), *(("--no-report", "--quiet") if command == "run" else ("--no-png",))])
    (line,) = o.stderr.splitlines()
    assert o.code == 2 and "stiffmap.db leads through a symbolic link to" in line, o.stderr
    assert "--allow-outside-paths" in line
    assert (tmp_path / "other.db").read_bytes() == b"another folder's results"
