"""``stiffmap run`` on simulated vision campaigns: resume after SIGKILL, bad inputs, the demo."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
import tomllib

import numpy as np
import pytest
from helpers.capture_campaigns import FAST_SIM
from helpers.cli_process import run_here, run_in_process, run_stiffmap

from stiffmap.camera import load_camera
from stiffmap.campaign.demo import demo_config
from stiffmap.campaign.runner import run_vision_campaign
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.store import Store, dump_content
from stiffmap.campaign.truth import load_truth
from stiffmap.cli.main import main
from stiffmap.errors import InputError
from stiffmap.report.browser import check_page, find_chromium

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """Four positions of the demo set-up, six loads (0.5 and 0.2 kg along +y, -x, -z: two
    magnitudes per direction, what K with an offset needs), two repeats (rendered once per module).

    With the true camera (no calibration views, 30 s less to render) and six loads rather
    than nine (two thirds of the images): these tests are about running, resuming and bad
    inputs; the quick demo below is measured with a calibrated camera and all nine loads.
    """
    cfg = demo_config(quick=True, repeats=2, calibration_views=0)
    cfg = dataclasses.replace(cfg, positions=cfg.positions[[0, 2, 4, 5]], loads=cfg.loads[:6])
    out = tmp_path_factory.mktemp("campaign") / "c"
    write_campaign(out, cfg, workers=1)
    return out


@pytest.fixture(scope="module")
def campaign_db(campaign, tmp_path_factory):
    """The campaign run once without interruption (one process): the database every resumed,
    killed or Dask run of it must equal, row for row."""
    a = _copy(campaign, tmp_path_factory.mktemp("ran") / "a")
    full = _run(a, "--workers", "1")
    assert full.returncode == 0, full.stderr
    return a / "stiffmap.db"


def _copy(src, dst):
    shutil.copytree(src, dst)
    return dst


def _run(path, *args):
    """``stiffmap run PATH --quiet --no-report ARGS`` in this process; a Dask run in its own
    process (its local cluster's scheduler and workers end with it)."""
    runner = run_stiffmap if "--dask" in args else run_here
    return runner("run", path, "--quiet", "--no-report", *args, columns=100)


def test_killed_run_resumes_to_the_same_database(campaign, campaign_db, tmp_path):
    b = _copy(campaign, tmp_path / "b")
    proc = _start_run(b, "--workers", "2")
    killed_at = _kill_when_measured(proc, b / "stiffmap.db", 1)
    assert killed_at is not None and killed_at < 4, "the run was not caught partway"
    again = _run(b, "--workers", "2")
    assert again.returncode == 0, again.stderr
    assert dump_content(b / "stiffmap.db") == dump_content(campaign_db)
    # A third run changes nothing and measures nothing.
    third = _run(b)
    assert "0 measured" in third.stdout and "4 unchanged" in third.stdout
    assert dump_content(b / "stiffmap.db") == dump_content(campaign_db)


def test_missing_image_and_wrong_camera_size_are_named_and_the_rest_goes_on(campaign, tmp_path):
    c = _copy(campaign, tmp_path / "c")
    gone = sorted((c / "images" / "p02").glob("l03_r01_loaded.png"))[0]
    gone.unlink()
    proc = _run(c)
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr
    assert "images/p02/l03_r01_loaded.png: image not found (position 2)" in proc.stderr
    summary = json.loads((c / "exports" / "summary.json").read_text())
    assert all(p["status"] == "ok" for p in summary["positions"])  # 11 of 12 loaded images are enough
    assert any("l03_r01_loaded.png" in f for f in summary["failures"])

    cam = json.loads((c / "camera.json").read_text())
    # The same camera at half the resolution (a file from another sensor mode): a plausible
    # camera, but not the one that took these images.
    cam["image_size"] = [1296, 972]
    for key in ("fx", "fy", "cx", "cy"):
        cam[key] /= 2
    (c / "camera.json").write_text(json.dumps(cam))
    proc = _run(c)
    # No position can be measured: exit 2, one line, the images' reason first.
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "no position could be measured" in proc.stderr
    assert re.search(r"images/p01/r01_unloaded\.png: .*2592.1944.*1296.972|1296.972.*2592.1944", proc.stderr)
    summary = json.loads((c / "exports" / "summary.json").read_text())
    assert all(p["status"] == "failed" for p in summary["positions"])


def test_position_outside_the_model_and_bad_spec(campaign, tmp_path):
    c = _copy(campaign, tmp_path / "c")
    spec = (c / "campaign.toml").read_text()
    first = re.search(r"list = \[\n\s*\[([^\]]*)\]", spec) or re.search(r"list = \[\[([^\]]*)\]", spec)
    assert first, spec
    spec = spec.replace(f"[{first.group(1)}]", "[0.0, 0.0, -900.0]", 1)
    (c / "campaign.toml").write_text(spec)
    proc = _run(c)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "position 1 (0, 0, -900): outside the model" in proc.stderr

    (c / "campaign.toml").write_text(spec.replace("repeats = 2", 'repeats = "two"'))
    proc = _run(c)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "campaign.toml" in lines[0] and "line" in lines[0] and "'repeats'" in lines[0]


def test_results_follow_the_positions_of_campaign_toml(campaign, tmp_path):
    """Dropping a position removes its results; moving one re-derives it from the same images."""
    c = _copy(campaign, tmp_path / "c")
    assert _run(c).returncode == 0
    # The report of a run campaign, (re)written from its directory.
    rep = run_here("report", c, "--no-png")
    assert rep.returncode == 0, rep.stderr
    assert "stiffness map" in (c / "report" / "index.html").read_text().lower()
    spec = (c / "campaign.toml").read_text()
    m = re.search(r"list = \[\[.*?\]\]", spec, re.S) or re.search(r"list = \[\n.*?\n\]", spec, re.S)
    assert m, spec
    pts = tomllib.loads(spec)["positions"]["list"]
    two = [pts[0], [pts[1][0] + 10.0, pts[1][1], pts[1][2]]]
    (c / "campaign.toml").write_text(spec.replace(m.group(0), f"list = {json.dumps(two)}"))
    proc = _run(c)
    assert proc.returncode == 0, proc.stderr
    assert "1 re-derived (images unchanged), 1 unchanged" in proc.stdout
    with Store(c / "stiffmap.db", read_only=True) as st:
        rows = [(r.position, r.x) for r in st.stiffness_rows()]
        assert rows == [(1, pts[0][0]), (2, pts[1][0] + 10.0)]
        for table, kept in (
            ("measurements", st.measurement_rows()),
            ("displacements", st.displacement_rows()),
            ("repeat_stats", st.repeat_stat_rows()),
            ("model_stiffness", st.model_stiffness_rows()),
        ):
            assert max(r.position for r in kept) == 2, table
    summary = json.loads((c / "exports" / "summary.json").read_text())
    assert [p["position"] for p in summary["positions"]] == [1, 2]

    # A 2-D position in a vision campaign is refused with its key and line.
    (c / "campaign.toml").write_text(spec.replace(m.group(0), "list = [[0.0, 0.0]]"))
    proc = _run(c)
    assert proc.returncode == 2
    assert "positions.list.0" in proc.stderr and "[x, y, z]" in proc.stderr and "line" in proc.stderr
    # No image at all (a wrong folder or pattern): one line, nothing done.
    (c / "campaign.toml").write_text(spec.replace("images/p", "pictures/p"))
    proc = _run(c)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "no image found" in proc.stderr


def test_a_reversed_load_axis_or_an_asymmetric_K_makes_the_run_exit_1(campaign, campaign_db, tmp_path):
    """The run of ``campaign`` exits 0 (``campaign_db``). (1) The +y loads written with the
    wrong sign in campaign.toml: every position's K is not positive definite, one warning a
    position names the y axis, exit 1. (2) One position's stored K made asymmetric by 30
    standard errors of K - K^T (its images unchanged, so reused): Holm's test over the 4
    positions flags it and only it, exit 1; (3) with the loads hung 40 mm off the measured
    point (loads.point_mm) asymmetry is not tested: one note says why, no warning for it."""
    a = _copy(campaign, tmp_path / "a")
    spec = (a / "campaign.toml").read_text()
    flipped = re.sub(r"force_n = \[0\.0, ([0-9.]+), 0\.0\]", r"force_n = [0.0, -\1, 0.0]", spec)
    assert flipped.count("force_n = [0.0, -") == 2, flipped
    (a / "campaign.toml").write_text(flipped)
    proc = _run(a)
    warned = [s for s in proc.stderr.splitlines() if s.startswith("warning: position ")]
    assert proc.returncode == 1 and len(warned) == 4, proc.stderr
    assert all("not positive definite: " in s and "det <= 0: " in s for s in warned), warned
    assert "the y axis (dy or fy of the wrong sign) looks reversed" in " ".join(proc.stderr.split())

    b = _copy(campaign_db.parent, tmp_path / "b")
    with Store(b / "stiffmap.db") as st:
        r = st.stiffness_rows()[1]
        assert not any(f.startswith("asymmetric") for f in r.flags)  # as measured
        # K[0,1] - K[1,0] moved by 30 of its standard errors (from K's covariance).
        sd = np.sqrt(r.K_cov[1, 1] + r.K_cov[3, 3] - 2 * r.K_cov[1, 3])
        K = r.K.copy()
        K[0, 1] += 30 * sd
        with st.transaction():
            st.conn.execute("UPDATE stiffness SET K=? WHERE position=?", (json.dumps(K.tolist()), r.position))
    proc = _run(b)
    warned = [s for s in proc.stderr.splitlines() if s.startswith("warning: position ")]
    assert proc.returncode == 1 and len(warned) == 1, proc.stderr
    assert warned[0].startswith(f"warning: position {r.position} (") and "K asymmetric: " in warned[0]
    assert "Holm's test at 1 % over the campaign's 4 positions" in " ".join(proc.stderr.split())
    summary = json.loads((b / "exports" / "summary.json").read_text())
    asym = [any(f.startswith("asymmetric") for f in p["flags"]) for p in summary["positions"]]
    assert asym == [False, True, False, False]

    spec = (b / "campaign.toml").read_text()
    (b / "campaign.toml").write_text(spec.replace("[loads]\n", "[loads]\npoint_mm = [0.0, 0.0, 40.0]\n", 1))
    proc = _run(b)
    assert "warning: position" not in proc.stderr, proc.stderr
    assert "note: K's asymmetry is not tested: the loads hang at loads.point_mm = (0, 0, 40) mm" in " ".join(
        proc.stderr.split()
    )
    summary = json.loads((b / "exports" / "summary.json").read_text())
    assert not any(f.startswith("asymmetric") for p in summary["positions"] for f in p["flags"])


# The quick demo (six positions at full size, 120 images and 20 calibration views: about 80 s
# to render and run) and what is measured on it are the long profile (`make test-long`, run by
# CI after `make test`); running, resuming and Dask are tested above and below on `campaign`.


@pytest.fixture(scope="module")
def quick_demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo"
    return run_stiffmap("demo", out, "--quick", "--workers", "2", columns=80), out


@pytest.mark.long
def test_quick_demo_recovers_the_true_stiffness(quick_demo):
    proc, out = quick_demo
    assert proc.returncode == 0, proc.stderr
    last = proc.stdout.strip().splitlines()[-1]
    m = re.fullmatch(r"worst relative K error: ([0-9.]+) %", last)
    assert m, last
    # The virtual test-bed's round trip (issue 4): every K within 2 % of truth.json, measured
    # as a lab does, with a camera calibrated from rendered views of a calibration board
    # (issue 17: under 3 %; measured 0.60 %, as with the true camera).
    assert float(m.group(1)) < 2.0
    assert "camera.json calibrated from 20 of 20 rendered views" in proc.stdout
    t = load_truth(out)
    assert t.data["generator"]["command"].endswith("calibration_views=20)")
    cam = load_camera(out / "camera.json")
    assert cam == t.calibrated_camera and cam != t.camera and cam.cov is not None
    # 20 views at 2592x1944: measured fx, fy within 0.002 %, the principal point within 0.1 px.
    for k in ("fx", "fy"):
        assert getattr(cam, k) == pytest.approx(getattr(t.camera, k), rel=2e-4)
    for k in ("cx", "cy"):
        assert getattr(cam, k) == pytest.approx(getattr(t.camera, k), abs=0.5)  # px
    page = (out / "report" / "index.html").read_text()
    assert "plotly" in page.lower() and "<script src=" not in page
    data = json.loads((out / "exports" / "summary.json").read_text())
    K = np.array([p["K"] for p in data["positions"]])
    truth = json.loads((out / "truth.json").read_text())
    Kt = np.array([p["K"] for p in truth["positions"]])
    rel = np.linalg.norm(K - Kt, axis=(1, 2)) / np.linalg.norm(Kt, axis=(1, 2))
    assert float(m.group(1)) == pytest.approx(100 * rel.max(), abs=0.006)


def test_init_from_demo_writes_the_quick_demo_campaign_ready_to_run(tmp_path, monkeypatch, capsys):
    """`stiffmap init DIR --from-demo`: the quick demo's campaign (demo_config(quick=True)),
    commented and ready to run.

    In-process, with demo_config cut to one position, six loads and no calibration views (the
    whole quick demo is rendered by the test above; that a simulation's files are the same byte
    for byte whoever writes them is tests/test_sim_campaign.py's determinism test).
    """

    def small(*, quick: bool = False, **kw):
        assert quick  # init --from-demo writes the quick demo
        cfg = demo_config(quick=True, repeats=1, calibration_views=0)
        return dataclasses.replace(cfg, positions=cfg.positions[:1], loads=cfg.loads[:6])

    monkeypatch.setattr("stiffmap.cli.campaign.demo_config", small)
    d = tmp_path / "my first campaign"
    assert main(["init", str(d), "--from-demo"]) in (0, None)
    said = capsys.readouterr().out
    assert "next: stiffmap run '" in said  # quoted: the path has spaces
    ref = tmp_path / "ref"
    write_campaign(ref, small(quick=True), workers=1)
    ours = sorted(p.relative_to(d) for p in (d / "images").rglob("*.png"))
    assert ours and ours == sorted(p.relative_to(ref) for p in (ref / "images").rglob("*.png"))
    assert (d / ours[-1]).read_bytes() == (ref / ours[-1]).read_bytes()
    spec = (d / "campaign.toml").read_text()
    assert "[x, y, z] in mm, base frame" in spec and "ISO 5725" in spec  # commented
    # Ready to run: stiffmap run measures it without a failure.
    assert main(["run", str(d), "--quiet", "--no-report", "--workers", "1"]) in (0, None)
    assert main(["init", str(d), "--from-demo"]) == 2
    assert "not empty" in capsys.readouterr().err


@pytest.mark.browser
@pytest.mark.long
def test_quick_demo_report_opens_in_chromium_without_console_error(quick_demo):
    if find_chromium() is None:
        pytest.skip("headless Chromium not found: apt-get install chromium (or set STIFFMAP_CHROMIUM)")
    proc, out = quick_demo
    assert proc.returncode == 0, proc.stderr
    r = check_page(out / "report" / "index.html", timeout=120)
    assert r.ready
    assert r.errors == ()
    assert r.external_requests == ()


# ------------------------------------------------------------------ guided capture (issue 15)

#: The quick demo's positions (1-based) the capture test takes at full size: the one its own
#: images measure worst (2: -67, -67, -200 mm, 0.60 %) and the far corner of the lowest plane
#: (6: 200, 200, -400 mm).
CAPTURED = (2, 6)


@pytest.mark.long
def test_capture_of_the_quick_demo_then_run_gives_the_demo_error(quick_demo, tmp_path):
    """Issue 15's must-show on the quick demo's own campaign (its campaign.toml, calibrated
    camera.json and truth.json; no image): `stiffmap capture --camera sim --yes`, then `stiffmap
    run`, gives K as close to the truth as the demo's own rendered images do, and every image was
    saved from frames taken with the platform settled (the simulated camera's truth).

    Two of the six positions (40 of the 120 images, 2592x1944 px, the campaign's [capture]
    defaults: 1 s settled; 40 s to capture, 5 s to run): the whole campaign takes 2 min to
    capture, benchmarks/bench_capture_demo.py (benchmarks/results/capture_demo.md: every
    position, worst K error 0.51 % captured against 0.60 % from the demo's images). Measured
    here: 0.40 and 0.43 % at positions 2 and 6, where the demo's images give 0.60 and 0.22 %.
    """
    proc, demo = quick_demo
    assert proc.returncode == 0, proc.stderr
    c = tmp_path / "captured"
    c.mkdir()
    for name in ("camera.json", "truth.json"):
        shutil.copy2(demo / name, c / name)
    spec = (demo / "campaign.toml").read_text()
    m = re.search(r"\[positions\]\n(?:#.*\n)*list = \[\n((?:  \[.*\],\n)+)\]", spec)
    rows = m.group(1).splitlines(keepends=True)
    (c / "campaign.toml").write_text(spec.replace(m.group(1), "".join(rows[i - 1] for i in CAPTURED)))
    cap = run_stiffmap("capture", c, "--camera", FAST_SIM, "--yes")
    assert cap.returncode == 0, cap.stderr
    assert "every image of the campaign is on disk" in cap.stdout
    log = [json.loads(line) for line in (c / "capture_log.jsonl").read_text().splitlines()]
    saved = [r for r in log if r["event"] == "saved"]
    assert len(saved) == 2 * 20 and log[-1]["event"] == "end"
    # The platform swung after each load change and move: frames were refused (6.8 frames per
    # image); every saved frame shows it settled, its swing's envelope below the camera's 1 um
    # vibration (at most 0.001 um measured), and the settle monitor's chi2 within its limit.
    frames = int(re.search(r"; (\d+) frames;", cap.stdout).group(1))
    assert frames > 4 * len(saved)
    for r in saved:
        assert r["source_truth"]["settled"] == [True], r
        assert max(r["source_truth"]["envelope_mm"]) < 1e-3
        assert r["settle"]["chi2_max"] <= r["settle"]["chi2_limit"]
    run = _run(c, "--workers", "2")
    assert run.returncode == 0, run.stderr
    truth = load_truth(demo)
    rel = lambda K, i: np.linalg.norm(K - truth.K[i]) / np.linalg.norm(truth.K[i])  # noqa: E731
    demo_K = [
        np.array(p["K"]) for p in json.loads((demo / "exports" / "summary.json").read_text())["positions"]
    ]
    err_demo = [rel(K, i) for i, K in enumerate(demo_K)]
    with Store(c / "stiffmap.db", read_only=True) as st:
        got = {r.position: r for r in st.stiffness_rows()}
    assert sorted(got) == [1, 2] and all(r.status == "ok" for r in got.values())
    err_cap = [rel(got[k + 1].K, i - 1) for k, i in enumerate(CAPTURED)]
    # One capture is one draw of the camera's noise and the robot's jitter, as one rendering of
    # the demo is: in three full captures the worst position was 0.51-0.95 % against the demo's
    # 0.60 % (capture_demo.md: settled 1, 0.6 and 0.4 s). The demo's error is its worst
    # position's; a capture is held to twice it (1.2 %; the demo's own bound is 2 %,
    # docs/simulation.md). A capture that does not wait for the platform to settle misses every
    # K by 5.6-6.8 % (capture_demo.md, settle_seconds = 0).
    assert max(err_demo) < 0.02
    assert max(err_cap) < 2 * max(err_demo), (err_cap, err_demo)
    # And in units of each run's own standard errors of K: the captured K is as far from the
    # truth as its uncertainty says, as the demo's are (measured: RMS over K's entries 1.03 and
    # 0.83 captured; 0.31-1.85 over the demo's six positions, the largest entry 3.2 sigma).
    for k, i in enumerate(CAPTURED):
        r = got[k + 1]
        z = (r.K - truth.K[i - 1]) / r.K_std
        assert np.sqrt(np.mean(z**2)) < 2.5 and np.abs(z).max() < 4.5, (i, z)


# ------------------------------------------------------------------ Dask (issue 14)


def _fresh_copy(campaign, dst):
    """The campaign without results: images hard-linked (read only), nothing measured."""
    skip = shutil.ignore_patterns("stiffmap.db*", "report", "exports")
    shutil.copytree(campaign, dst, copy_function=os.link, ignore=skip)
    return dst


def test_dask_local_run_gives_the_local_run_database(campaign, campaign_db, tmp_path):
    """`stiffmap run --dask local`: the database of `stiffmap run` in one process, row for row.
    The workers see the campaign directory and read the images there."""
    c = _fresh_copy(campaign, tmp_path / "c")
    done = _run(c, "--dask", "local", "--workers", "2")
    assert done.returncode == 0, done.stderr
    assert "images read by the workers from the campaign directory (shared storage)" in done.stdout
    assert dump_content(c / "stiffmap.db") == dump_content(campaign_db)


def test_killed_dask_client_resumes_to_the_same_database(campaign, campaign_db, tmp_path):
    """SIGKILL of `stiffmap run --dask local` partway (the client, then its orphaned local
    cluster), then a re-run: the same database as an uninterrupted run."""
    c = _fresh_copy(campaign, tmp_path / "c")
    proc = _start_run(c, "--dask", "local", "--workers", "2")
    killed_at = _kill_when_measured(proc, c / "stiffmap.db", 1)
    assert killed_at is not None and killed_at < 4, "the run was not caught partway"
    again = _run(c, "--dask", "local", "--workers", "2")
    assert again.returncode == 0, again.stderr
    assert f"{4 - killed_at} measured" in again.stdout
    assert dump_content(c / "stiffmap.db") == dump_content(campaign_db)


def _start_run(path, *args):
    """`stiffmap run PATH ARGS` started in its own process group (to be killed), warnings as errors."""
    return subprocess.Popen(
        [sys.executable, "-m", "stiffmap", "run", str(path), "--quiet", "--no-report", *args],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=dict(os.environ, PYTHONWARNINGS="error"),
    )


def _kill_when_measured(proc, db, n_positions, timeout=180):
    """SIGKILL ``proc`` (the client first, then its process group) once ``db`` holds
    ``n_positions`` positions; how many it held (None: the run ended first)."""
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if db.exists():
                try:
                    with Store(db, read_only=True, timeout=0.1) as st:
                        n = len(st.stiffness_rows())
                except (sqlite3.OperationalError, InputError):  # being created: no tables yet
                    n = 0
                if n >= n_positions:
                    os.kill(proc.pid, signal.SIGKILL)
                    return n
            time.sleep(0.02)
        return None
    finally:
        proc.wait(timeout=30)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # the local cluster the client left behind


def test_a_worker_killed_during_a_run_loses_and_duplicates_nothing(campaign, campaign_db, tmp_path):
    """A Dask worker SIGKILLed while it measures a position (a cluster of 2 workers, given to
    `run` by its scheduler's address, the images sent to them): its task runs again elsewhere,
    the run completes, and the database is the uninterrupted run's, row for row."""
    distributed = pytest.importorskip("distributed")
    c = _fresh_copy(campaign, tmp_path / "c")
    killed: list[int] = []
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, dashboard_address=":0", silence_logs=logging.CRITICAL
        ) as cluster,
        distributed.Client(cluster, set_as_default=False) as client,
    ):

        def progress(done, total, measured):
            if measured and not killed:  # a position is in: kill a worker busy with another
                busy = [w for w, keys in client.processing().items() if keys]
                pid = client.run(os.getpid, workers=busy[:1])
                killed.extend(pid.values())
                os.kill(killed[0], signal.SIGKILL)

        summary = run_vision_campaign(
            c, workers=2, dask=cluster.scheduler_address, send_images=True, progress=progress
        )
    assert killed, "no worker was busy when the first position came in"
    assert summary.failures == [] and summary.measured == 4
    assert len(summary.notes) == 1 and "left the cluster during the run" in summary.notes[0]
    assert "images sent to the workers" in summary.backend
    assert dump_content(c / "stiffmap.db") == dump_content(campaign_db)


def test_an_unreachable_scheduler_is_one_line(campaign, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("stiffmap.parallel.CONNECT_TIMEOUT_S", 0.5)
    c = _copy(campaign, tmp_path / "c")
    code, _, err = run_in_process(["run", c, "--quiet", "--dask", "tcp://127.0.0.1:9"], monkeypatch, capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "--dask tcp://127.0.0.1:9: cannot reach the Dask scheduler" in err and "dask scheduler" in err
    assert not (c / "stiffmap.db").exists()  # nothing done
