"""A new robot kind through the registry alone: a toy gantry reaches `stiffmap model`, `fit`, a
campaign (`stiffmap simulate` then `stiffmap run`) and the report, with no other file changed.

The gantry is written here, as a newcomer would write a new mechanism's module, and registered
with :func:`stiffmap.kinds.registered` (one entry). Its stiffness is checked against the
closed form written in the test; the campaign's fitted ram stiffness against the value the
test-bed simulated.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from typing import ClassVar

import numpy as np
import pytest
from helpers.cli_process import run_in_process
from helpers.fuzz_campaign import small_vision_config

from stiffmap.campaign.store import DB_NAME, Store
from stiffmap.kinds import RobotKind, TestBed, build_with_params, registered
from stiffmap.models.base import (
    IKSolution,
    Mechanism,
    as_points,
    check_positive,
    model_map,
    static_error_of,
    stiffness_of,
)
from stiffmap.sim.robot import mechanism_robot

BOX = np.array([[-300.0, 300.0], [-300.0, 300.0], [-500.0, -100.0]])  # x, y, z travel, mm


@dataclass(frozen=True)
class Gantry:
    """A Cartesian gantry: x, y, z drives (springs kx, ky, kz, N/mm) and a vertical ram whose
    tip bends sideways: its compliance grows with the cube of the ram's extension below
    z = 0 (a cantilever; k_ram, N/mm, is its lateral stiffness at 100 mm)."""

    kx: float = 400.0
    ky: float = 300.0
    kz: float = 120.0
    k_ram: float = 300.0

    name: ClassVar[str] = "gantry"
    dim: ClassVar[int] = 3

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_positive(f.name, getattr(self, f.name), "N/mm"))

    @classmethod
    def param_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    def params(self) -> dict[str, float]:
        return {n: getattr(self, n) for n in self.param_names()}

    def with_params(self, **params) -> Gantry:
        bad = sorted(set(params) - set(self.param_names()))
        if bad:
            raise ValueError(f"unknown gantry parameter(s) {', '.join(bad)}")
        return replace(self, **params)

    def describe(self) -> str:
        return "gantry " + ", ".join(f"{k}={v:g}" for k, v in self.params().items())

    def inverse_kinematics(self, points) -> IKSolution:
        P, _ = as_points(points, 3)
        inside = np.all((P >= BOX[:, 0]) & (P <= BOX[:, 1]), axis=1)
        q = np.where(inside[:, None], P, np.nan)
        reasons = tuple("" if ok else "unreachable: outside the gantry's travel" for ok in inside)
        return IKSolution(q, inside, reasons)

    def evaluate(self, points):
        P, _ = as_points(points, 3)
        ik = self.inverse_kinematics(P)
        ram = (np.clip(-P[:, 2], 0.0, None) / 100.0) ** 3 / self.k_ram
        C = np.zeros((len(P), 3, 3))
        C[:, 0, 0] = 1 / self.kx + ram
        C[:, 1, 1] = 1 / self.ky + ram
        C[:, 2, 2] = 1 / self.kz
        K = np.linalg.inv(C)
        ones = np.where(ik.reachable, 1.0, np.nan)
        return model_map(self.name, self.params(), P, K, ik.reachable, ik.reasons, ik.q, ones)

    def stiffness(self, points):
        return stiffness_of(self, points)

    def static_error(self, points, force):
        return static_error_of(self, points, force)


def gantry4() -> np.ndarray:
    """Four positions of the gantry (mm)."""
    return np.array(
        [[0.0, 0.0, -310.0], [120.0, -60.0, -250.0], [-120.0, 60.0, -380.0], [60.0, 90.0, -220.0]]
    )


def gantry2() -> np.ndarray:
    """Two positions that a small camera sees (the test's campaign: a few small images)."""
    return np.array([[50.0, 0.0, -300.0], [30.0, -20.0, -300.0]])


#: A camera of 300 x 700 px looking at the boards at those positions (as the fuzz tests' seed).
SMALL_SCENE = small_vision_config().scene


def _closed_form_K(g: Gantry, p) -> np.ndarray:
    """K of the gantry at p, written out: the drives' and the ram's compliances in series."""
    e = max(-p[2], 0.0)
    c_ram = (e / 100.0) ** 3 / g.k_ram
    return np.diag([1 / (1 / g.kx + c_ram), 1 / (1 / g.ky + c_ram), g.kz])


GANTRY = RobotKind(
    name="gantry",
    summary="a toy Cartesian gantry (a test)",
    build=lambda d: build_with_params(Gantry, d),
    dim=3,
    param_units={"kx": "N/mm", "ky": "N/mm", "kz": "N/mm", "k_ram": "N/mm"},
    default_fit=("k_ram",),
    default_load=(10.0, "x"),
    positions={"gantry4": gantry4, "gantry2": gantry2},
    testbed=TestBed(
        name="gantry",
        instrument="camera",
        positions="gantry2",
        robot=lambda params, **kw: mechanism_robot(Gantry().with_params(**params), **kw),
        scene=lambda camera: SMALL_SCENE,
    ),
)


@pytest.fixture(scope="module")
def gantry():
    with registered(GANTRY) as kind:
        yield kind


def test_the_gantry_is_a_mechanism():
    assert isinstance(Gantry(), Mechanism)


def test_stiffmap_model_maps_the_new_kind(gantry, monkeypatch, capsys):
    code, out, err = run_in_process(
        ["model", "gantry", "--param", "k_ram=500", "--json"], monkeypatch, capsys
    )
    assert code == 0, err
    recs = json.loads(out)
    g = Gantry(k_ram=500.0)
    assert len(recs) == 4  # its registered positions
    for r, p in zip(recs, gantry4(), strict=True):
        K = _closed_form_K(g, p)
        np.testing.assert_allclose(r["K"], K, rtol=1e-12)
        # The kind's default load, 10 N along x: u = K^-1 F.
        np.testing.assert_allclose([r["ux"], r["uy"], r["uz"]], np.linalg.solve(K, [10.0, 0, 0]), rtol=1e-12)
    # Its parameters are checked by name, in the command line's words.
    code, _, err = run_in_process(["model", "gantry", "--param", "k_rim=5"], monkeypatch, capsys)
    assert code == 2 and "--param: unknown gantry parameter k_rim; valid: kx, ky, kz, k_ram" in err


def test_stiffmap_fit_recovers_the_new_kinds_parameter(gantry, tmp_path, monkeypatch, capsys):
    true = Gantry(k_ram=640.0)
    P = gantry4()
    rows = ["x,y,z," + ",".join(f"k{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3))]
    rows += [",".join(f"{float(v)!r}" for v in (*p, *_closed_form_K(true, p).ravel())) for p in P]
    f = tmp_path / "K.csv"
    f.write_text("\n".join(rows) + "\n")
    code, out, err = run_in_process(["fit", "gantry", f, "--json"], monkeypatch, capsys)
    assert code == 0, err
    res = json.loads(out)
    assert list(res["parameters"]) == ["k_ram"]  # the kind's default fit
    assert res["parameters"]["k_ram"]["estimate"] == pytest.approx(640.0, rel=1e-9)


@pytest.mark.slow
def test_a_campaign_of_the_new_kind_runs_and_reports(gantry, tmp_path, monkeypatch, capsys):
    """simulate (the test-bed renders its field) -> run (K per position, the kind's fit) -> report."""
    loads = tmp_path / "loads.csv"  # four loads identify K with an offset
    loads.write_text("fx,fy,fz,label\n0,4.9,0,+y\n-4.9,0,0,-x\n0,0,-4.9,-z\n0,2,0,+y small\n")
    out = tmp_path / "gantry"
    code, _, err = run_in_process(
        ["simulate", out, "--robot", "gantry", "--param", "k_ram=250", "--loads", loads, "--repeats", "1",
         "--true-camera", "--no-noise", "--repeatability-mm", "0", "--jitter-mm", "0", "--workers", "1",
         "--json"],
        monkeypatch, capsys,
    )  # fmt: skip
    assert code == 0, err
    code, _, err = run_in_process(["run", out, "--workers", "1", "--json"], monkeypatch, capsys)
    assert code == 0, err
    with Store(out / DB_NAME) as store:
        fit = store.model_fit("stiffness")
        rows = store.stiffness_rows()
    assert fit.status == "ok" and fit.model == "gantry"
    est = fit.params
    # The ram's stiffness from K measured at two positions through a small camera, without
    # noise (none in the images, none in the robot's positioning): the chain's own bias,
    # measured at 0.4 %.
    assert est["k_ram"] == pytest.approx(250.0, rel=0.02)
    K = np.array([r.K for r in rows])
    Kt = np.array([_closed_form_K(Gantry(k_ram=250.0), p) for p in gantry2()])
    lateral = (0, 1)
    np.testing.assert_allclose(K[:, lateral, lateral], Kt[:, lateral, lateral], rtol=0.03)
    page = (out / "report" / "index.html").read_text(encoding="utf-8")
    assert "gantry" in page and "k_ram" in page
