"""Fuzz classes of the surfaces added since the first readers: rigs, results databases, Dask.

Every class starts from valid inputs written by the library's own simulators:

- :func:`rig_seed`: a small campaign seen by a rig of two cameras (the test-bed's scene at half
  the reference camera's resolution, the cameras 30 degrees apart about the vertical, one
  position of the Delta robot, four load cases: 10 images of 972 x 729 px), with its
  ``rig.json``; ``stiffmap run`` measures it in under two seconds, ``pose --rig`` one image set
  in half a second;
- :func:`helpers.fuzz_campaign.bare_vision_seed` and the sensor seed with the ``stiffmap.db``
  of a run on each (:func:`measured_seed`).

Then one thing is made wrong as a careless or unlucky user would:

- ``rig.json``: one value of the file (an extreme or non-finite number, a wrong type, a key
  dropped or added), or the rig itself: the cameras' names swapped, a camera moved by 50 mm
  or turned by 3 degrees, a camera dropped or one more added, absurdly large numbers (a
  camera 1e200 mm away, a std of 1e10 px, a covariance of 1e308), a camera.json in its place;
- ``stiffmap.db``: one stored value of one row (NULL, NaN, a 2x2 K, a list where parameters
  belong, text, huge numbers, deep nesting), a row deleted, another program's tables;
- ``--dask``: a malformed address, a port where nothing listens, or a server on this machine
  that is not a Dask scheduler (:mod:`helpers.fake_servers`: HTTP, SSH, a hang-up, binary
  bytes read as a frame length of exbibytes).

:data:`FUZZ_CLASSES` lists them for ``tests/test_fuzz_safety.py`` and
``benchmarks/bench_fuzz.py``.
"""

from __future__ import annotations

import functools
import json
import shutil
import sqlite3
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from helpers import fake_servers
from helpers.board_scenes import scaled_camera
from helpers.fuzz import FuzzCase, FuzzClass, run_argv
from helpers.fuzz_campaign import RUN, CampaignCase, bare_vision_seed, sensor_seed
from helpers.fuzz_vision import malformed_json
from stiffmap.camera import reference_camera
from stiffmap.campaign.simulated import write_campaign
from stiffmap.geometry import matrix_from_rotvec
from stiffmap.loads import paper9
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import default_scene, with_cameras
from stiffmap.sim.testbed import SimConfig

__all__ = ["FUZZ_CLASSES", "rig_seed", "measured_seed", "rig_pose_argv"]


def _read_tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@functools.cache
def rig_seed() -> dict[str, bytes]:
    """The files of the small rig campaign (relative path -> bytes)."""
    scene = with_cameras(default_scene(scaled_camera(reference_camera(), 0.5)), 2, angle_deg=30.0)
    cfg = SimConfig(
        scene=scene,
        robot=delta_robot(),
        positions=np.array([[-66.67, 66.67, -310.0]]),
        loads=tuple(paper9())[:4],
        repeats=1,
        seed=11,
        robot_stays=True,
        calibration_views=0,
        name="fuzz seed: a rig of two cameras",
    )
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        write_campaign(d / "c", cfg, workers=1)
        return _read_tree(d / "c")
    finally:
        shutil.rmtree(d, ignore_errors=True)


@functools.cache
def measured_seed(kind: str = "vision") -> dict[str, bytes]:
    """:func:`helpers.fuzz_campaign.bare_vision_seed` (or the sensor seed) with the ``stiffmap.db``
    of a run on it."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        for name, data in (bare_vision_seed() if kind == "vision" else sensor_seed()).items():
            (d / name).parent.mkdir(parents=True, exist_ok=True)
            (d / name).write_bytes(data)
        o = run_argv([a.replace("{dir}", str(d)) for a in RUN])
        if o.code != 0:
            raise RuntimeError(f"the seed campaign does not run: exit {o.code}: {o.stderr[-500:]}")
        return {k: v for k, v in _read_tree(d).items() if not k.startswith("exports/")}
    finally:
        shutil.rmtree(d, ignore_errors=True)


# ------------------------------------------------------------------------------- rig.json
#: The image set ``pose --rig`` measures: the unloaded images of the seed's position.
RIG_SET = "images/p01/r01_unloaded_{camera}.png"


def rig_pose_argv(image_set: str = RIG_SET) -> tuple[str, ...]:
    """``stiffmap pose --rig rig.json SET --board 6x5 --square-mm 10 --json`` (the mobile board)."""
    return (
        "pose",
        "--rig",
        "{dir}/rig.json",
        f"{{dir}}/{image_set}",
        "--board",
        "6x5",
        "--square-mm",
        "10",
        "--json",
    )


def _moved(T: list, draw) -> list:
    """``cam2rig`` moved by 50 mm along an axis or turned by 3 degrees about one."""
    M = np.array(T, dtype=float)
    axis = draw(st.integers(0, 2))
    if draw(st.booleans()):
        M[axis, 3] += draw(st.sampled_from((50.0, -50.0)))
    else:
        r = np.zeros(3)
        r[axis] = np.radians(draw(st.sampled_from((3.0, -3.0))))
        M[:3, :3] = matrix_from_rotvec(r) @ M[:3, :3]
    return M.tolist()


@st.composite
def rig_json(draw, valid: str) -> tuple[bytes, str]:
    """A wrong ``rig.json`` and what is wrong with it."""
    d = json.loads(valid)
    cams = d["cameras"]
    kind = draw(
        st.sampled_from(
            ("value", "value", "swap", "move", "drop", "third", "huge", "first", "camera.json", "cov")
        )
    )
    if kind == "value":
        return draw(malformed_json(valid)), "rig.json: one value"
    if kind == "swap":
        cams[0]["name"], cams[1]["name"] = cams[1]["name"], cams[0]["name"]
    elif kind == "move":
        cams[1]["cam2rig"] = _moved(cams[1]["cam2rig"], draw)
    elif kind == "drop":
        del cams[draw(st.integers(0, 1))]
        cams[0]["cam2rig"] = np.eye(4).tolist()
    elif kind == "third":
        cams.append({**cams[1], "name": draw(st.sampled_from(("cam3", "cam1 ", "", "x/y", "{camera}")))})
    elif kind == "huge":
        where, value = draw(
            st.sampled_from(
                (
                    ("t", 1e200),
                    ("t", 1e6),
                    ("std", {"fx": 1e10}),
                    ("std", {"fx": 1e200}),
                    ("std", {"dist": [1e5, 0, 0, 0, 0]}),
                    ("std", {"cx": 1e300, "fy": 1e-300}),
                )
            )
        )
        c = cams[draw(st.integers(0, 1))] if where == "std" else cams[1]
        if where == "t":
            c["cam2rig"][draw(st.integers(0, 2))][3] = value * draw(st.sampled_from((1, -1)))
        else:
            c["std"] = value
    elif kind == "first":
        cams[0]["cam2rig"] = cams[1]["cam2rig"]
    elif kind == "camera.json":
        d = {k: v for k, v in cams[draw(st.integers(0, 1))].items() if k not in ("name", "cam2rig")}
    elif kind == "cov":
        names = [f"{c['name']}.{p}" for c in cams for p in ("fx", "fy", "cx", "cy")]
        value = draw(st.sampled_from((1e308, 1e200, 1e12, 1.0, 0.0, -1.0)))
        M = np.eye(len(names)) * value
        if draw(st.booleans()):
            M[0, 1] = M[1, 0] = 2 * abs(value)  # correlations beyond 1
        d["cov"] = {"params": names, "matrix": M.tolist()}
    return json.dumps(d).encode(), f"rig.json: {kind}"


@st.composite
def rig_cases(draw) -> FuzzCase:
    """``pose --rig`` on one image set, or ``run``, with a wrong rig.json."""
    files = dict(rig_seed())
    text, note = draw(rig_json(files["rig.json"].decode()))
    files["rig.json"] = text
    if draw(st.booleans()):
        # A camera dropped, added or renamed: the message may name its images instead.
        blamed = None if note.endswith(("swap", "drop", "third", "camera.json")) else "rig.json"
        return CampaignCase(files=files, argv=rig_pose_argv(), blamed=blamed, note=note)
    return CampaignCase(files=files, argv=(*RUN, "--json"), blamed=None, note=note)


# ---------------------------------------------------------------------------- stiffmap.db
#: Values put into one column of one row of the results database.
DB_VALUES = (
    None,
    "NaN",
    "[NaN]",
    "[[NaN, 0, 0], [0, 1, 0], [0, 0, 1]]",
    "[[1, 2], [3, 4]]",
    "[[1]]",
    "[]",
    "{}",
    "[1, 2]",
    '"x"',
    '{"k_theta": "a"}',
    '{"k_theta": null}',
    "[1e400]",
    "1e999",
    "[" * 5000 + "]" * 5000,
    "not json",
    1e308,
    -1,
    0,
    "x" * 100_000,
    b"\xff\xfe\x00",
)


@st.composite
def db_cases(draw) -> FuzzCase:
    """``report`` or ``run`` on the measured seed with one stored value, row or table made wrong."""
    seed = draw(st.sampled_from(("vision", "vision", "sensor")))
    files = dict(measured_seed(seed))
    kind = draw(st.sampled_from(("value", "value", "value", "delete", "foreign")))
    d = Path(tempfile.mkdtemp(prefix="stiffmap-db-"))
    try:
        db = d / "stiffmap.db"
        db.write_bytes(files["stiffmap.db"])
        conn = sqlite3.connect(db)
        tables = [
            r[0]
            for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")
            if r[0] != "sqlite_sequence"
        ]
        table = draw(st.sampled_from(sorted(tables)))
        if kind == "value":
            cols = [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]
            col = draw(st.sampled_from(cols))
            value = draw(st.sampled_from(DB_VALUES))
            try:
                conn.execute(
                    f"UPDATE {table} SET {col} = ? WHERE rowid = (SELECT min(rowid) FROM {table})", (value,)
                )
            except sqlite3.IntegrityError:  # NOT NULL, a key already there
                pass
            note = f"{table}.{col} = {str(value)[:30]!r}"
        elif kind == "delete":
            conn.execute(f"DELETE FROM {table} WHERE rowid = (SELECT min(rowid) FROM {table})")
            note = f"a row of {table} deleted"
        else:
            conn.execute(
                draw(
                    st.sampled_from(
                        ("CREATE TABLE users (a)", "CREATE VIEW v AS SELECT 1", "DROP TABLE meta")
                    )
                )
            )
            note = "another program's objects"
        conn.commit()
        conn.close()
        files["stiffmap.db"] = db.read_bytes()
    finally:
        shutil.rmtree(d, ignore_errors=True)
    argv = draw(st.sampled_from((("report", "{dir}", "--no-png"), RUN, (*RUN, "--json"))))
    return CampaignCase(files=files, argv=argv, blamed=None, note=f"stiffmap.db ({seed}): {note}")


# --------------------------------------------------------------------------------- --dask
#: Addresses a user may type for a scheduler's (ports below 1024 on this machine: none listens).
DASK_ADDRESSES = (
    "tcp://127.0.0.1:9",
    "tcp://127.0.0.1:1",
    "tcp://no-such-host.invalid:8786",
    "127.0.0.1:8786",
    "tcp://127.0.0.1",
    "tcp://127.0.0.1:99999",
    "tcp://127.0.0.1:-1",
    "tcp://:8786",
    "http://127.0.0.1:8787",
    "udp://127.0.0.1:8786",
    "inproc://x",
    "tls://127.0.0.1:9",
    "tcp://[::1]:9",
    "tcp://127.0.0.1:8786/status",
    "",
    " ",
    "tcp://" + "a" * 300 + ":8786",
    "tcp://127.0.0.1:８７８６",
)


@st.composite
def dask_cases(draw) -> FuzzCase:
    """``run --dask ADDRESS`` on the bare seed: a malformed address, nothing there, or a server
    that is not a Dask scheduler (started on this machine on first use; not those that wait
    for the time limit of 15 s: they are in tests/test_parallel.py, with a shorter one)."""
    if draw(st.booleans()):
        address = fake_servers.server(
            draw(
                st.sampled_from(tuple(k for k in fake_servers.KINDS if k not in ("http", "silent", "short")))
            )
        )
    else:
        address = draw(st.sampled_from(DASK_ADDRESSES))
    files = dict(bare_vision_seed())
    argv = ("run", "{dir}", "--quiet", "--no-report", "--dask", address)
    return CampaignCase(files=files, argv=argv, blamed=None, note=f"--dask {address!r}")


def names_the_dask_option(case: FuzzCase, stderr: str, code: int | None) -> bool:
    """A ``--dask`` case ends in exit 2 whose one error line starts with ``--dask`` (or ``error: --dask``)."""
    lines = [ln for ln in stderr.splitlines() if ln.startswith("error:")]
    return code == 2 and len(lines) == 1 and "--dask" in lines[0]


FUZZ_CLASSES: list[FuzzClass] = [
    FuzzClass(
        "rig.json x pose --rig, run",
        rig_cases(),
        "the rig campaign's rig.json: one value mutated, the cameras swapped, one moved 50 mm or "
        "turned 3 degrees, one dropped or added, numbers of 1e6 to 1e308, a camera.json instead",
    ),
    FuzzClass(
        "stiffmap.db values x report, run",
        db_cases(),
        "one stored value of a measured campaign's database (NULL, NaN, 2x2 K, lists for objects, "
        "text, 1e308, deep nesting), a row deleted, another program's table or view",
    ),
    FuzzClass(
        "--dask addresses x run",
        dask_cases(),
        "malformed scheduler addresses, ports where nothing listens, and servers on this machine "
        "that are not Dask's (HTTP, SSH, SMTP, a hang-up, binary frame lengths of exbibytes)",
    ),
]
