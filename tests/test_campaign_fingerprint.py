"""A model fit kept with the fingerprint of the robot it fitted (issue 27: a spec whose robot changed
after the run).

Before: editing campaign.toml's robot after ``stiffmap run`` (a geometry parameter, a URDF's bytes,
the tip frame) left the stored fit in use: ``report`` drew it on the new robot and ``compensate
--from-campaign`` corrected programs with it, exit 0 and no word. Now ``report`` leaves it out with
one warning naming what changed (exit 1) and ``compensate --from-campaign`` refuses (exit 2).
"""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest
from helpers.fuzz import run_argv
from helpers.fuzz_safety import ROBOTS, _with_robot, measured_seed

from stiffmap.campaign.fingerprint import robot_changes, robot_fingerprint
from stiffmap.campaign.fitted import fitted_model
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import SCHEMA_VERSION, Store, dump_content, to_json
from stiffmap.errors import InputError

SCHEMA3 = Path(__file__).parent / "data" / "schema3"


def _copy_schema3(tmp_path: Path) -> Path:
    root = tmp_path / "c"
    shutil.copytree(SCHEMA3, root)
    return root


def _edit(root: Path, old: str, new: str) -> None:
    spec = root / "campaign.toml"
    text = spec.read_text()
    assert old in text
    spec.write_text(text.replace(old, new))


def test_a_database_of_schema_3_is_migrated_in_place_with_its_rows_kept(tmp_path):
    """The fixture was written by stiffmap before the fingerprint (tests/data/schema3/README.md)."""
    db = _copy_schema3(tmp_path) / "stiffmap.db"
    before = dump_content(db)
    assert "robot" not in {r[1] for r in sqlite3.connect(db).execute("PRAGMA table_info(model_fit)")}
    with Store(db) as store:
        fit = store.model_fit("static_error")
    after = dump_content(db)
    conn = sqlite3.connect(db)
    assert conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()[0] == str(
        SCHEMA_VERSION
    )
    assert fit is not None and fit.status == "ok" and fit.robot is None and fit.info is None
    have = {r[1] for r in conn.execute("PRAGMA table_info(model_fit)")}
    assert {"robot", "info"} <= have  # schema 4's column and schema 5's
    for table, rows in before.items():
        if table == "meta":
            continue
        extra = len(after[table][0]) - len(rows[0]) if rows else 0
        assert [r[: len(r) - extra] for r in after[table]] == rows, table
    assert after["model_fit"][0][-2:] == (None, None)  # the new columns, unknown for an old fit


def test_an_old_fit_is_used_and_a_fingerprinted_one_refused_once_the_robot_changed(tmp_path):
    root = _copy_schema3(tmp_path)
    assert fitted_model(root).names == ("kj",)  # no fingerprint (schema 3): cannot be checked
    with Store(root / "stiffmap.db") as store:  # as 'stiffmap run' now stores it
        store.conn.execute(
            "UPDATE model_fit SET robot=?", (to_json(robot_fingerprint(load_spec(root), root)),)
        )
    assert fitted_model(root).names == ("kj",)
    _edit(root, "kj = 700.0", "kj = 500.0")  # the fitted parameter's starting value: the fit replaces it
    assert fitted_model(root).names == ("kj",)
    _edit(root, "h = 800.0", "h = 700.0")
    with pytest.raises(InputError, match=r"robot changed since the run \(robot\.params\.h\)"):
        fitted_model(root)


def test_the_fingerprint_names_a_urdf_file_edited_and_a_tip_frame_changed(tmp_path):
    root = _copy_schema3(tmp_path)
    (root / "robot.urdf").write_bytes((ROBOTS / "arm6.urdf").read_bytes())
    joints = ", ".join(f"k{i} = 1e6" for i in range(1, 7))
    robot = f'model = "urdf"\nurdf = "robot.urdf"\ntip_frame = "tool0"\nparams = {{{joints}}}'
    (root / "campaign.toml").write_bytes(_with_robot((root / "campaign.toml").read_text(), robot))
    stored = robot_fingerprint(load_spec(root), root)
    assert robot_changes(stored, load_spec(root), root) == []
    urdf = root / "robot.urdf"
    urdf.write_text(urdf.read_text().replace("<robot", "<!-- edited -->\n<robot", 1))
    assert robot_changes(stored, load_spec(root), root) == ["robot.urdf file"]
    _edit(root, 'tip_frame = "tool0"', 'tip_frame = "flange"')
    assert robot_changes(stored, load_spec(root), root) == ["robot.tip_frame", "robot.urdf file"]
    # A fitted joint's starting value is no change; the fit list is.
    assert robot_changes(stored, load_spec(root), root, fitted=["k1"]) == robot_changes(
        stored, load_spec(root), root
    )


@pytest.mark.slow  # a sensor campaign run (about 3 s), then report and compensate
def test_report_leaves_out_and_compensate_refuses_the_fit_of_a_changed_robot(tmp_path):
    root = tmp_path / "c"
    for name, data in measured_seed("sensor").items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    assert run_argv(["report", str(root), "--no-png"]).code == 0
    text = (root / "campaign.toml").read_text()
    assert "L = 250.0" in text
    (root / "campaign.toml").write_text(text.replace("L = 250.0", "L = 260.0"))
    o = run_argv(["report", str(root), "--no-png"])
    warnings = [ln for ln in o.stderr.splitlines() if ln.startswith("warning:")]
    assert o.code == 1 and len(warnings) == 1, o.stderr
    assert "robot changed since the run (robot.params.L)" in warnings[0]
    program = tmp_path / "p.ngc"
    program.write_text("G1 X400 Y300 F100\nG1 X410 Y300\n")
    argv = [
        "compensate",
        "--from-campaign",
        str(root),
        "--path",
        str(program),
        "--out",
        str(tmp_path / "o.ngc"),
    ]
    o = run_argv([*argv, "--force-n", "100,0"])
    (line,) = o.stderr.strip().splitlines()
    assert o.code == 2 and "robot changed since the run (robot.params.L)" in line, o.stderr
    assert str(root / "campaign.toml") in line
    assert not (tmp_path / "o.ngc").exists()
