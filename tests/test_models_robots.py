"""Robot descriptions as published (issue 29): every URDF of a public collection loads, and what
``stiffmap model urdf --json`` prints equals an independent computation from the file's numbers.

The collection is ``example-robot-data`` (PyPI, a dev dependency): 69 URDFs of arms (UR3/5/10,
Panda, Kinova, xArm7, Z1, SO-100/101), two-armed and mobile robots (Baxter, PR2, TIAGo),
humanoids and quadrupeds, written by their makers and labs with all the clutter a published
description has (transmissions, gazebo tags, mimic joints, package:// meshes, many branches).
For each, the measured point is the link at the end of its longest chain of moving joints;
at random configurations within the joint limits, the tip position, K and K6 are checked
against ``helpers.urdf_reference`` (NumPy forward kinematics from the file's origins, axes and
mimic tags, the Jacobian by central differences, C = J K^-1 J^T) to 1e-6 relative.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import sys
from importlib.metadata import distribution
from pathlib import Path

import numpy as np
import pytest
from helpers import urdf_reference as ref

from stiffmap.cli.main import run

OFFSET = (10.0, -20.0, 30.0)  # mm in the tip frame
TOL = 1e-6  # relative, the issue's


def _robots_dir() -> Path:
    return Path(
        str(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
    )


ROBOTS = sorted(_robots_dir().rglob("*.urdf"))


def _deepest_link(links, joints) -> tuple[str | None, int]:
    """The link with the most moving joints between it and its root (the first in file order)."""
    best, tip = 0, None
    for lk in links:
        n = sum(joints[j].type in ref.MOVING for j in ref.path(joints, lk))
        if n > best:
            best, tip = n, lk
    return tip, best


def _limits(joints, coords) -> tuple[np.ndarray, np.ndarray]:
    """Sampling ranges (rad, mm): the file's limits within +-pi (+-100 mm for a prismatic joint)."""
    lo, hi = [], []
    for c in coords:
        j = joints[c]
        s = 1000.0 if j.type == "prismatic" else 1.0
        inf = 100.0 if j.type == "prismatic" else math.pi
        lo.append(max(j.lower * s, -inf))
        hi.append(min(j.upper * s, inf))
    return np.array(lo), np.array(hi)


def _reference(joints, chain, coords, q, k):
    """Tip position, K, K6 (None where singular) and the translation rank measure, independently."""
    p, _ = ref.tip_pose_mm(joints, chain, coords, q, OFFSET)
    J = ref.jacobian_fd(joints, chain, coords, q, OFFSET)
    C = J @ np.diag(1.0 / k) @ J.T
    s = np.linalg.svd(J[:3], compute_uv=False)
    trans = s[-1] / s[0] if s.size >= 3 and s[0] > 0 else 0.0
    K = np.linalg.inv(C[:3, :3]) if trans > 1e-6 else None
    K6 = (
        np.linalg.inv(C)
        if len(coords) >= 6 and np.linalg.matrix_rank(J, tol=1e-9 * np.abs(J).max()) == 6
        else None
    )
    return p, K, K6, trans


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _write_configs(path: Path, joints, coords, Q) -> None:
    cols = [f"{c}_{'mm' if joints[c].type == 'prismatic' else 'deg'}" for c in coords]
    rows = [",".join(["label", *cols])]
    for i, q in enumerate(Q):
        vals = [
            v if joints[c].type == "prismatic" else math.degrees(v) for c, v in zip(coords, q, strict=True)
        ]
        rows.append(",".join([f"c{i + 1}", *(repr(float(v)) for v in vals)]))
    path.write_text("\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """Every URDF of the collection through ``stiffmap model urdf --json``: (name, outcome) pairs."""
    mp = pytest.MonkeyPatch()
    out = []
    rng = np.random.default_rng(29)
    tmp = tmp_path_factory.mktemp("robots")
    try:
        for f in ROBOTS:
            out.append((str(f.relative_to(_robots_dir())), _one(f, rng, tmp, mp)))
    finally:
        mp.undo()
    return out


def _one(f: Path, rng, tmp: Path, mp) -> dict:
    text = f.read_text()
    links, joints = ref.read_joints(text)
    tip, _ = _deepest_link(links, joints)
    res: dict = {"tip": tip}
    if tip is None:
        res["expect_refusal"] = "no moving joint in the file"
    try:
        chain = ref.path(joints, tip) if tip else []
        coords = ref.coordinates(joints, chain) if tip else []
    except KeyError as e:  # a mimic naming a joint the file does not define
        res["expect_refusal"] = f"mimic of missing joint {e}"
        coords = []
    Q = []
    if coords:
        lo, hi = _limits(joints, coords)
        Q = rng.uniform(lo, hi, size=(3, len(coords)))
    k = np.array(
        [rng.uniform(2e5, 2e6) if joints[c].type == "prismatic" else rng.uniform(2e7, 2e8) for c in coords]
    )
    cfg = tmp / f"{f.stem}_configs.csv"
    if coords:
        _write_configs(cfg, joints, coords, Q)
    else:
        cfg.write_text("q1_deg\n0\n")
    args = ["model", "urdf", f, "--tip", tip or "base_link", "--tip-offset-mm", ",".join(map(str, OFFSET))]
    args += ["--configs", cfg, "--param", "k_theta=" + (",".join(f"{v:.17g}" for v in k) or "1e8"), "--json"]
    code, out, err = _run(args, mp)
    res.update(
        code=code, out=out, err=err, joints=joints, chain=chain if tip else [], coords=coords, Q=Q, k=k
    )
    return res


def _run(args, mp):
    """``stiffmap ARGS`` in this process (the module fixture has no capsys): (status, stdout, stderr)."""
    o, e = io.StringIO(), io.StringIO()
    mp.setattr(sys, "argv", ["stiffmap", *map(str, args)])
    code = 0
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        try:
            run()
        except SystemExit as ex:
            code = ex.code or 0
    return code, o.getvalue(), e.getvalue()


def _no_k_anywhere(r) -> bool:
    """The reference finds no K at any of the robot's configurations (a planar two-joint chain)."""
    return bool(r["coords"]) and all(
        _reference(r["joints"], r["chain"], r["coords"], q, r["k"])[1] is None for q in r["Q"]
    )


def test_every_published_description_loads_or_is_refused_for_a_real_reason(sweep):
    for _, r in sweep:
        if r["code"] == 2 and "expect_refusal" not in r and _no_k_anywhere(r):
            r["expect_refusal"] = "the joints cannot move the point in every direction"
            assert "singular: the joints cannot move the point along" in r["err"], r["err"]
    refused = {name: r["err"].strip() for name, r in sweep if r["code"] == 2 and "expect_refusal" in r}
    unexpected = [
        (name, r["err"].strip()) for name, r in sweep if r["code"] == 2 and "expect_refusal" not in r
    ]
    assert not unexpected, "\n".join(f"{a}: {b}" for a, b in unexpected)
    missed = [name for name, r in sweep if "expect_refusal" in r and r["code"] != 2]
    assert not missed, missed
    # The refusals, each one line naming the file and why (listed in docs/models.md).
    for name, line in refused.items():
        f = Path(name)
        assert line.startswith("error: ") and line.count("\n") == 0, line
        assert f.name in line or f"{f.stem}_configs.csv" in line, line
    assert len(sweep) == len(ROBOTS) >= 60
    assert len(refused) <= 12, refused


def test_tip_position_k_and_k6_equal_an_independent_computation(sweep):
    checked_k = checked_k6 = 0
    for name, r in sweep:
        if r["code"] == 2:
            continue
        recs = json.loads(r["out"])
        assert len(recs) == len(r["Q"]), name
        for rec, q in zip(recs, r["Q"], strict=True):
            types = [r["joints"][c].type for c in r["coords"]]
            q_file = [
                v if t == "prismatic" else math.radians(v) for t, v in zip(types, rec["q_deg"], strict=True)
            ]
            np.testing.assert_allclose(q_file, q, rtol=1e-9, atol=1e-9)
            p, K, K6, trans = _reference(r["joints"], r["chain"], r["coords"], q, r["k"])
            if "error" in rec:
                # Refused only where the joints (almost) cannot move the point in every direction,
                # or at a joint singularity: the reference sees it too.
                assert "singular" in rec["error"] or "beyond" in rec["error"], (name, rec["error"])
                continue
            assert _rel(rec["position"], p) < TOL or np.linalg.norm(np.subtract(rec["position"], p)) < 1e-9
            assert K is not None, (name, trans)
            e = _rel(rec["K"], K)
            assert e < TOL, (name, e)
            checked_k += 1
            if rec["K6"] is not None:
                assert K6 is not None, name
                e6 = _rel(rec["K6"], K6)
                assert e6 < TOL, (name, e6)
                checked_k6 += 1
    assert checked_k >= 100 and checked_k6 >= 60, (checked_k, checked_k6)
