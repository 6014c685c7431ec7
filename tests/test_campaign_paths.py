"""What a campaign reads and where: path safety, a run that measures nothing, a damaged database.

Through the real command (``helpers.cli_process.run_here``), on the small simulated
campaigns of :mod:`helpers.fuzz_campaign` (two positions and four load cases of the
virtual Delta test-bed; two LDV recordings of the 3PRR). Issue 16, "Never a traceback":

- file names in ``campaign.toml`` and in index files stay inside their directory (after
  resolving ``..``, absolute paths and symbolic links) unless ``--allow-outside-paths``;
  the refusal names the file, the key (or line and column), the name and the option;
- a run in which no position could be measured says so (it used to crash);
- a results database that is not one is named, and neither it nor a raw input is changed.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest
from helpers.cli_process import assert_one_line_error, run_here
from helpers.fuzz_campaign import sensor_seed, vision_seed, vision_seed_with_results

OPTION = "--allow-outside-paths"


def _write(root: Path, files: dict[str, bytes]) -> Path:
    for name, data in files.items():
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)
    return root


def _digests(root: Path) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _edit_spec(root: Path, old: str, new: str) -> None:
    spec = root / "campaign.toml"
    text = spec.read_text(encoding="utf-8")
    assert old in text
    spec.write_text(text.replace(old, new), encoding="utf-8")


# ------------------------------------------------------------------ campaign.toml


def test_recording_named_through_dotdot_is_refused_then_allowed(tmp_path):
    c = _write(tmp_path / "c", sensor_seed())
    (tmp_path / "elsewhere").mkdir()
    os.replace(c / "recordings/trace_000.csv", tmp_path / "elsewhere/trace_000.csv")
    _edit_spec(c, '"recordings/trace_000.csv"', '"recordings/../../elsewhere/trace_000.csv"')
    before = _digests(tmp_path)
    proc = run_here("run", c, "--no-report")
    assert proc.returncode == 2
    line = assert_one_line_error(
        proc,
        str(c / "campaign.toml"),
        "key 'sensor.recordings[0].file'",
        "'recordings/../../elsewhere/trace_000.csv'",
        "goes up with '..'",
        OPTION,
    )
    assert "outside the campaign directory" in line
    assert _digests(tmp_path) == before  # refused before anything was written
    proc = run_here("run", c, "--no-report", "--json", OPTION)
    assert proc.returncode == 0, proc.stderr
    rows = {r["file"]: r for r in json.loads(proc.stdout)["sensor_results"]}
    assert rows["recordings/../../elsewhere/trace_000.csv"]["status"] == "ok"


def test_absolute_camera_file_is_refused_then_allowed(tmp_path):
    c = _write(tmp_path / "c", vision_seed())
    cam = tmp_path / "calibration" / "camera.json"
    cam.parent.mkdir()
    os.replace(c / "camera.json", cam)
    _edit_spec(c, 'file = "camera.json"', f"file = {json.dumps(str(cam))}")
    proc = run_here("run", c, "--quiet", "--no-report", "--workers", "1")
    assert proc.returncode == 2
    assert_one_line_error(proc, "campaign.toml", "key 'camera.file'", repr(str(cam)), "absolute path", OPTION)
    assert not (c / "stiffmap.db").exists()
    proc = run_here("run", c, "--quiet", "--no-report", "--workers", "1", OPTION)
    assert proc.returncode == 0, proc.stderr
    # The report reads the camera file too (its calibration section): the same rule.
    proc = run_here("report", c, "--no-png")
    assert proc.returncode == 2
    assert_one_line_error(proc, "campaign.toml", "key 'camera.file'", "absolute path", OPTION)
    proc = run_here("report", c, "--no-png", OPTION)
    assert proc.returncode == 0, proc.stderr
    assert (c / "report" / "index.html").is_file()


def test_image_pattern_leading_outside_names_the_image(tmp_path):
    c = _write(tmp_path / "c", vision_seed())
    _edit_spec(
        c,
        'loaded = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png"',
        'loaded = "../shared/p{position:02d}_l{load:02d}.png"',
    )
    proc = run_here("run", c, "--quiet", "--no-report", "--workers", "1")
    assert proc.returncode == 2
    assert_one_line_error(
        proc,
        "campaign.toml",
        "key 'images.loaded' (position 1, load 1, repeat 1)",
        "'../shared/p01_l01.png'",
        OPTION,
    )


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links here")
def test_symbolic_link_leading_outside_is_refused(tmp_path):
    c = _write(tmp_path / "c", sensor_seed())
    os.replace(c / "recordings", tmp_path / "recordings")
    (c / "recordings").symlink_to(tmp_path / "recordings", target_is_directory=True)
    proc = run_here("run", c, "--no-report")
    assert proc.returncode == 2
    assert_one_line_error(
        proc,
        "campaign.toml",
        "key 'sensor.recordings[0].file'",
        "symbolic link",
        str(tmp_path / "recordings"),
        OPTION,
    )
    proc = run_here("run", c, "--no-report", OPTION)
    assert proc.returncode == 0, proc.stderr


def test_dotdot_that_stays_inside_is_fine(tmp_path):
    c = _write(tmp_path / "c", sensor_seed())
    _edit_spec(c, '"recordings/trace_000.csv"', '"recordings/../recordings/trace_000.csv"')
    proc = run_here("run", c, "--no-report")
    assert proc.returncode == 0, proc.stderr


# -------------------------------------------------------------------- index files


def test_index_naming_a_recording_outside_its_folder(tmp_path):
    files = sensor_seed()
    c = _write(tmp_path / "c", files)
    index = c / "recordings" / "index.csv"
    lines = index.read_text(encoding="utf-8").splitlines()
    assert "trace_000.csv" in lines[1]
    os.replace(c / "recordings/trace_000.csv", c / "trace_000.csv")
    lines[1] = lines[1].replace("trace_000.csv", "../trace_000.csv")
    index.write_text("\n".join(lines) + "\n", encoding="utf-8")
    proc = run_here("sensor", "--index", index)
    assert proc.returncode == 2
    assert_one_line_error(
        proc, str(index), "line 2, column 'file'", "'../trace_000.csv'", "goes up with '..'", OPTION
    )
    proc = run_here("sensor", "--index", index, "--json", OPTION)
    assert proc.returncode == 0, proc.stderr


# ------------------------------------------------------- nothing measured, a bad database


def test_run_where_no_position_can_be_measured(tmp_path):
    files = dict(vision_seed())
    blank = files["images/p01/r01_unloaded.png"]
    for name in files:  # every image shows the unloaded scene of position 1 cut short: unreadable
        if name.startswith("images/"):
            files[name] = blank[: len(blank) // 3]
    c = _write(tmp_path / "c", files)
    proc = run_here("run", c, "--quiet", "--workers", "1")
    assert proc.returncode == 2
    line = assert_one_line_error(
        proc, str(c), "no position could be measured (2 failed)", "images/p01/r01_unloaded.png: truncated PNG"
    )
    assert "no report written" in line
    assert (c / "stiffmap.db").is_file()  # the failures are recorded: summary.json lists them all
    summary = json.loads((c / "exports" / "summary.json").read_text())
    assert len(summary["failures"]) >= 2
    proc = run_here("report", c, "--no-png")
    assert proc.returncode == 2
    assert_one_line_error(proc, str(c), "no position has results")


@pytest.mark.parametrize(
    "content",
    [b"not a database\n" * 100, b"SQLite format 3\x00" + bytes(4096), "damaged"],
    ids=["text", "header only", "damaged"],
)
def test_damaged_results_database_is_named_and_left_alone(tmp_path, content):
    c = _write(tmp_path / "c", vision_seed_with_results())
    db = c / "stiffmap.db"
    if content == "damaged":  # the seed's own database, a block of its pages overwritten
        data = bytearray(db.read_bytes())
        data[100:4096] = b"\xa5" * (4096 - 100)
        content = bytes(data)
    db.write_bytes(content)
    before = _digests(c)
    for argv in (("run", c, "--quiet", "--no-report", "--workers", "1"), ("report", c, "--no-png")):
        proc = run_here(*argv)
        assert proc.returncode == 2, proc.stderr
        assert_one_line_error(proc, str(db), "move it away")
        assert _digests(c) == before  # nothing repaired, deleted or lost; the raw inputs untouched
    assert not (c / "stiffmap.db-wal").exists() or (c / "stiffmap.db-wal").stat().st_size == 0
