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
- ``campaign.toml``'s [robot] after the run: another kind, or one parameter of the same robot
  (``report`` must warn and ``compensate --from-campaign`` refuse, naming it);
- ``--dask``: a malformed address, a port where nothing listens, or a server on this machine
  that is not a Dask scheduler (:mod:`helpers.fake_servers`: HTTP, SSH, a hang-up, binary
  bytes read as a frame length of exbibytes).

:data:`FUZZ_CLASSES` lists them for ``tests/test_fuzz_safety.py`` and
``benchmarks/bench_fuzz.py``.
"""

from __future__ import annotations

import functools
import json
import re
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
        name = draw(st.sampled_from(("cam3", "cam1 ", "", "x/y", "{camera}")))
        cams.append({**cams[1], "name": name})
        kind = f"third {name!r}"
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


#: The rig mistakes that give plausible poses: what a warning (pose --rig) or a failure (run)
#: must say of them.
_MUST_SAY = {
    "rig.json: swap": "cameras disagree",
    "rig.json: move": "cameras disagree",
    "rig.json: first": "cameras disagree",
}


@st.composite
def rig_cases(draw) -> FuzzCase:
    """``pose --rig`` on one image set, or ``run``, with a wrong rig.json."""
    files = dict(rig_seed())
    text, note = draw(rig_json(files["rig.json"].decode()))
    files["rig.json"] = text
    expect = _MUST_SAY.get(note)
    if draw(st.booleans()):
        # A camera dropped, added or renamed: the message may name its images instead; cameras
        # that disagree (a value of cam2rig changed too) are a warning on the image set (exit 1)
        # that says "the rig file", what it says is ``expect``.
        blamed = (
            None
            if expect is not None
            or note.startswith(
                ("rig.json: drop", "rig.json: third", "rig.json: camera.json", "rig.json: one value")
            )
            else "rig.json"
        )
        return CampaignCase(files=files, argv=rig_pose_argv(), blamed=blamed, note=note, expect=expect)
    if note == "rig.json: third 'cam3'":  # a camera whose images do not exist
        expect = "camera cam3 measured nothing"
    return CampaignCase(files=files, argv=(*RUN, "--json"), blamed=None, note=note, expect=expect)


# ----------------------------------------------------------------- one camera's images
def _damaged_image(kind: str, data: bytes, other: bytes) -> bytes | None:
    """One camera's image made wrong (None: the file removed; b"/": a folder in its place)."""
    if kind == "missing":
        return None
    if kind == "truncated":
        return data[: max(1, len(data) // 3)]
    if kind == "empty":
        return b""
    if kind == "text":
        return b"not an image\n"
    if kind == "wrong size":
        return _half_size(data)
    if kind == "folder":
        return b"/"
    return other  # "the other camera's": the two cameras' files exchanged


def _half_size(data: bytes) -> bytes:
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    ok, buf = cv2.imencode(".png", img[::2, ::2])
    return buf.tobytes()


@st.composite
def rig_image_cases(draw) -> FuzzCase:
    """``run`` on the rig seed with one camera's images damaged: all of them, or some."""
    files = dict(rig_seed())
    cam, other_cam = draw(st.sampled_from((("cam1", "cam2"), ("cam2", "cam1"))))
    kind = draw(
        st.sampled_from(("missing", "truncated", "empty", "text", "wrong size", "folder", "exchanged"))
    )
    mine = sorted(k for k in files if k.endswith(f"_{cam}.png"))
    every = draw(st.booleans())
    chosen = (
        mine
        if every
        else draw(st.lists(st.sampled_from(mine), min_size=1, max_size=len(mine) - 1, unique=True))
    )
    folders = []
    for k in chosen:
        new = _damaged_image(kind, files[k], files[k.replace(f"_{cam}.png", f"_{other_cam}.png")])
        if kind == "exchanged":
            twin = k.replace(f"_{cam}.png", f"_{other_cam}.png")
            files[twin] = files[k]
        if new is None or new == b"/":
            del files[k]
            if new == b"/":
                folders.append(k)
        else:
            files[k] = new
    for k in folders:  # a folder where the image belongs: a file inside it makes it exist
        files[f"{k}/x"] = b""
    expect = None
    if every:
        expect = "cameras disagree" if kind == "exchanged" else f"camera {cam} measured nothing"
    note = f"{cam}'s images, {'all' if every else f'{len(chosen)} of {len(mine)}'}: {kind}"
    return CampaignCase(files=files, argv=(*RUN, "--json"), blamed=None, note=note, expect=expect)


# ---------------------------------------------------------------------- [robot] and its file
ROBOTS = Path(__file__).resolve().parents[2] / "src" / "stiffmap" / "models" / "robots"
_JOINTS = {f"k{i}": 1e6 for i in range(1, 7)}


def _with_robot(spec: str, robot: str) -> bytes:
    """campaign.toml with its [robot] section replaced by ``robot`` (TOML lines)."""
    import re

    return re.sub(
        r"\[robot\]\n(?:.*\n)*?(?=\n\[)", lambda m: "[robot]\n" + robot + "\n", spec, count=1
    ).encode()


def _toml_inline(d: dict) -> str:
    return "{" + ", ".join(f"{k} = {v!r}".replace("inf", "inf") for k, v in d.items()) + "}"


@st.composite
def _robot_file(draw, key: str, good: bytes, suffix: str) -> tuple[str, dict, dict, bool, str]:
    """Where ``robot.<key>`` points and what is there: (name, files, links, refused, note)."""
    where = draw(
        st.sampled_from(
            ("in", "in", "in", "missing", "up", "absolute", "link out", "link in", "folder", "empty")
        )
    )
    content = good
    if where == "in" and draw(st.integers(0, 3)) == 0:
        content = draw(
            st.sampled_from(
                (good[: len(good) // 2], b"", b"\xff\xfe", b"<robot" if suffix == ".urdf" else b"x = [")
            )
        )
        where = "in, damaged"
    name = f"robot{suffix}"
    files: dict[str, bytes] = {}
    links: dict[str, str] = {}
    if where.startswith("in"):
        files[f"c/{name}"] = content
    elif where == "missing":
        name = f"nope{suffix}"
    elif where == "up":
        files[f"outside{suffix}"] = good
        name = f"../outside{suffix}"
    elif where == "absolute":
        files[f"outside{suffix}"] = good
        name = "{dir}/outside" + suffix
    elif where == "link out":
        files[f"outside{suffix}"] = good
        links[f"c/{name}"] = f"outside{suffix}"
    elif where == "link in":
        files[f"c/models/{name}"] = good
        links[f"c/{name}"] = f"c/models/{name}"
    elif where == "folder":
        files[f"c/{name}/x"] = b""
    elif where == "empty":
        name = ""
    refused = where not in ("in", "link in")
    return name, files, links, refused, f"{key} {where}"


@st.composite
def robot_cases(draw) -> FuzzCase:
    """``run`` on the bare vision seed with a [robot] of a URDF arm, of legs or the Delta, its file
    put in, out of or missing from the campaign and its keys made wrong; a case that is
    certainly wrong must be refused before any image is measured (exit 2)."""
    seed = {f"c/{k}": v for k, v in bare_vision_seed().items()}
    spec = seed.pop("c/campaign.toml").decode()
    kind = draw(st.sampled_from(("urdf", "urdf", "legs", "delta")))
    lines, refused, notes = [f'model = "{kind}"'], False, []
    files, links = dict(seed), {}
    if kind in ("urdf", "legs"):
        key, suffix = ("urdf", ".urdf") if kind == "urdf" else ("legs", ".toml")
        good = (ROBOTS / ("arm6.urdf" if kind == "urdf" else "delta.toml")).read_bytes()
        name, more, links, bad, note = draw(_robot_file(key, good, suffix))
        files.update(more)
        lines.append(f'{key} = "{name}"')
        refused, notes = refused or bad, [note]
    params: dict = dict(_JOINTS) if kind == "urdf" else {}
    fit = None
    if kind == "urdf":
        tip = draw(st.sampled_from(("tool0", "tool0", "link_3", "nope", "")))
        lines.append(f'tip_frame = "{tip}"')
        refused = refused or tip in ("nope", "")
        notes.append(f"tip_frame {tip!r}")
    change = draw(
        st.sampled_from(("none", "none", "extra param", "fit unknown", "fit rigid", "fit one", "param value"))
    )
    if change == "extra param":
        params["k7" if kind == "urdf" else "k9"] = 1.0
        refused = True
    elif change == "fit unknown":
        fit = ["k9"]
        refused = True
    elif change == "fit rigid" and kind == "legs":
        fit = ["k_arm"]
        refused = True
    elif change == "fit one":
        fit = ["k1"] if kind == "urdf" else ["k_theta"]
    elif change == "param value":
        target = "k1" if kind == "urdf" else "k_theta"
        value = draw(st.sampled_from((-1.0, 0.0, 1e300, float("inf"), 1e-300)))
        params[target] = value
        refused = refused or value <= 0
    notes.append(change)
    if params:
        lines.append("params = " + _toml_inline(params))
    if fit is not None:
        lines.append(f"fit = {fit!r}".replace("'", '"'))
    files["c/campaign.toml"] = _with_robot(spec, "\n".join(lines))
    argv = ("run", "{dir}/c", "--quiet", "--workers", "1", "--no-report")
    return CampaignCase(
        files=files,
        argv=argv,
        blamed=None,
        note=f"{kind}: " + "; ".join(notes),
        must_refuse=refused,
        links=links,
    )


# ------------------------------------------------------------------------------ capture
@functools.cache
def capture_seed() -> dict[str, bytes]:
    """A campaign to capture (:func:`helpers.capture_campaigns.small_campaign`, one position, one
    load case: two images), no image on disk, ``[capture] timeout_s = 1``."""
    import tomllib

    from helpers.capture_campaigns import small_campaign
    from helpers.fuzz_campaign import toml_dumps

    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        root = small_campaign(d / "c", positions=(1,), timeout=1.0)
        spec = tomllib.loads((root / "campaign.toml").read_text(encoding="utf-8"))
        spec["loads"]["cases"] = spec["loads"]["cases"][:1]
        (root / "campaign.toml").write_text(toml_dumps(spec), encoding="utf-8")
        return _read_tree(root)
    finally:
        shutil.rmtree(d, ignore_errors=True)


#: Values of the simulated camera's options (``--camera sim:KEY=VALUE``), sane and absurd.
SIM_VALUES = ("5", "0.1", "1.7", "1e9", "1e-9", "1e308", "1e-300", "0", "-1", "nan", "inf", "x", "", "1e400")


@st.composite
def capture_cases(draw) -> FuzzCase:
    """``capture --camera sim:... [--frames N] --yes`` on the capture seed (timeout_s = 1)."""
    from stiffmap.capture.cameras import SIM_OPTIONS

    base = {"fps": "5", "time_constant_s": "0.1", "frequency_hz": "1.7"}
    items = dict(base)
    for _ in range(draw(st.integers(1, 2))):
        key = draw(st.sampled_from((*SIM_OPTIONS, "fps", "fps", "time_constant_s", "shutter")))
        items[key] = draw(st.sampled_from(SIM_VALUES))
    camera = "sim:" + ",".join(f"{k}={v}" for k, v in items.items())
    if draw(st.integers(0, 9)) == 0:
        camera = draw(
            st.sampled_from(("sim:", "sim:fps", "sim:fps=5,fps=6", "sim:,,", "sim:fps=5=5", "simx"))
        )
    argv = ["capture", "{dir}", "--camera", camera, "--yes"]
    if draw(st.booleans()):
        frames = draw(st.sampled_from(("1", "2", "0", "-1", "1001", "1000000000", "1e9", "x", "")))
        argv += ["--frames", frames]
    return CampaignCase(files=dict(capture_seed()), argv=tuple(argv), blamed=None, note=camera)


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


#: [robot] sections a campaign.toml may hold after a run made with another (the seeds': the
#: Delta for the vision seed, the 3PRR for the sensor seed).
CHANGED_ROBOTS = (
    'model = "3prr"',
    'model = "delta"',
    'model = "none"',
    'model = "legs"\nlegs = "robot.toml"',
    'model = "legs"\nlegs = "robot.toml"\nfit = ["k_theta"]',
    'model = "urdf"\nurdf = "arm6"\ntip_frame = "tool0"\nparams = {k1 = 1e6, k2 = 1e6, k3 = 1e6, k4 = 1e6, '
    "k5 = 1e6, k6 = 1e6}",
    'model = "delta"\nparams = {arm_length = 1e300}',
    'model = "delta"\nfit = ["k_arm"]',
)


#: The seeds' robots with one value changed after the run (the fit is then another robot's:
#: silently wrong before the fingerprint), and the part of the fingerprint that names it; None:
#: only the starting value of the fitted parameter changed (the fit replaces it: no change).
SAME_KIND_CHANGES = {
    "vision": (
        ("arm_length = 310.0", "robot.params.arm_length"),
        ("forearm_length = 420.0", "robot.params.forearm_length"),
        ("k_theta = 2.0e5", None),
    ),
    "sensor": (("h = 780.0", "robot.params.h"), ("kb = 9000.0", "robot.params.kb"), ("kj = 500.0", None)),
}
#: A program ``compensate --from-campaign`` corrects with the sensor seed's fit (3PRR, mm).
_PROGRAM = b"G1 X400 Y300 F100\nG1 X410 Y300\n"


def _same_kind_change(draw, seed: str, files: dict[str, bytes]) -> tuple[str, str | None]:
    """One value of the seed's [robot] params changed: (the new TOML line's value, the part named)."""
    text = files["campaign.toml"].decode()
    new, part = draw(st.sampled_from(SAME_KIND_CHANGES[seed]))
    name = new.split(" = ")[0]
    changed = re.sub(rf"\b{name} = [-+0-9.e]+", new, text, count=1)
    assert changed != text, (seed, new)
    files["campaign.toml"] = changed.encode()
    return new, part


@st.composite
def changed_robot_cases(draw) -> FuzzCase:
    """``report`` on a measured seed whose [robot] was changed after the run (another kind, or
    one of its parameters: then the report warns naming it), or ``compensate --from-campaign``
    on the sensor seed whose 3PRR changed (refused, naming it)."""
    seed = draw(st.sampled_from(("vision", "sensor")))
    files = dict(measured_seed(seed))
    if draw(st.booleans()):
        new, part = _same_kind_change(draw, seed, files)
        expect = None if part is None else f"robot changed since the run ({part})"
        if seed == "sensor" and draw(st.booleans()):
            files["p.ngc"] = _PROGRAM
            argv = ("compensate", "--from-campaign", "{dir}", "--path", "{dir}/p.ngc", "--out", "{dir}/o.ngc")
            return CampaignCase(
                files=files,
                argv=(*argv, "--force-n", "100,0"),
                blamed=None if part is None else "campaign.toml",
                note=f"sensor: robot.params {new!r} after the run",
                expect=expect,
                must_refuse=part is not None,
            )
        return CampaignCase(
            files=files,
            argv=("report", "{dir}", "--no-png"),
            blamed=None,
            note=f"{seed}: robot.params {new!r} after the run",
            expect=expect,
        )
    robot = draw(st.sampled_from(CHANGED_ROBOTS))
    files["campaign.toml"] = _with_robot(files["campaign.toml"].decode(), robot)
    files["robot.toml"] = (ROBOTS / "delta.toml").read_bytes()
    return CampaignCase(
        files=files, argv=("report", "{dir}", "--no-png"), blamed=None, note=f"{seed}: [robot] now {robot!r}"
    )


@st.composite
def db_cases(draw) -> FuzzCase:
    """``report`` or ``run`` on the measured seed with one stored value, row or table made wrong
    (or, one case in six, ``report`` after its [robot] section changed)."""
    if draw(st.integers(0, 5)) == 0:
        return draw(changed_robot_cases())
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
        slow=True,
    ),
    FuzzClass(
        "one camera's images x run (rig)",
        rig_image_cases(),
        "all or some of one camera's images of the rig campaign missing, truncated, empty, text, "
        "of half the size, folders, or exchanged with the other camera's",
        slow=True,
    ),
    FuzzClass(
        "[robot] and its file x run",
        robot_cases(),
        "a URDF arm, legs or the Delta: the robot file in the campaign, damaged, missing, a "
        "folder, up with '..', absolute, a symbolic link out or in; tip frames, parameters and "
        "fit names unknown, rigid, negative, huge: what is certainly wrong must be refused "
        "before any image is measured",
        slow=True,
    ),
    FuzzClass(
        "capture options x capture",
        capture_cases(),
        "the simulated camera's options (frame rates, time constants, frequencies of 1e-300 to "
        "1e400, NaN, text, unknown keys) and --frames (0 to 1e9, text) on a campaign of two images "
        "with timeout_s = 1",
        slow=True,
    ),
    FuzzClass(
        "stiffmap.db values x report, run",
        db_cases(),
        "one stored value of a measured campaign's database (NULL, NaN, 2x2 K, lists for objects, "
        "text, 1e308, deep nesting), a row deleted, another program's table or view; report after "
        "campaign.toml's [robot] changed",
        slow=True,
    ),
    FuzzClass(
        "[robot] changed after the run x report, compensate",
        changed_robot_cases(),
        "a measured campaign whose [robot] was edited after the run: another kind, a rigid or absurd "
        "parameter, or one geometry parameter of the same robot (the fit then another robot's: "
        "report warns naming it, compensate --from-campaign refuses); the fitted parameter's "
        "starting value (no change)",
        slow=True,
    ),
    FuzzClass(
        "--dask addresses x run",
        dask_cases(),
        "malformed scheduler addresses, ports where nothing listens, and servers on this machine "
        "that are not Dask's (HTTP, SSH, SMTP, a hang-up, binary frame lengths of exbibytes)",
        slow=True,
    ),
]
