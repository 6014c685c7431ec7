"""A newcomer's first steps with a campaign: ``stiffmap init``, then run, report, capture.

A campaign given by its campaign.toml is taken as ``stiffmap run`` takes it, by ``report`` and
``capture`` too (``report`` asked for an OUT_DIR, "give OUT_DIR, the directory to write the
report to", and ``capture`` looked for ``CAMPAIGN/campaign.toml/campaign.toml``); running the
example before giving it a camera file is one error line (an empty progress bar,
``measuring images 0/? -- images/s``, came before it).
"""

from __future__ import annotations

from helpers.cli_process import run_in_process


def _campaign(tmp_path, monkeypatch, capsys):
    code, _, err = run_in_process(["init", tmp_path / "c"], monkeypatch, capsys)
    assert code == 0, err
    return tmp_path / "c"


def test_report_of_a_campaign_toml_is_its_campaigns(tmp_path, monkeypatch, capsys):
    root = _campaign(tmp_path, monkeypatch, capsys)
    code, _, err = run_in_process(["report", root / "campaign.toml"], monkeypatch, capsys)
    # the same answer as for the directory: nothing run there yet
    assert code == 2 and err.count("\n") == 1, err
    assert "no results yet (stiffmap.db missing)" in err and "OUT_DIR" not in err


def test_capture_of_a_campaign_toml_reads_that_campaign(tmp_path, monkeypatch, capsys):
    root = _campaign(tmp_path, monkeypatch, capsys)
    argv = ["capture", root / "campaign.toml", "--camera", "sim", "-y"]
    code, _, err = run_in_process(argv, monkeypatch, capsys)
    # the example campaign.toml names camera.json, which init does not write: that file is named
    assert code == 2 and err.count("\n") == 1, err
    assert f"{root.resolve() / 'camera.json'}: camera file not found" in err and "campaign.toml/" not in err


def test_running_the_example_before_its_camera_file_is_one_error_line(tmp_path, monkeypatch, capsys):
    root = _campaign(tmp_path, monkeypatch, capsys)
    code, out, err = run_in_process(["run", root], monkeypatch, capsys)
    assert (code, out) == (2, ""), err
    assert (
        err == f"error: {root.resolve() / 'camera.json'}: camera file not found (the camera file that "
        "camera.file in campaign.toml names)\n"
    )
