"""``stiffmap model`` and ``stiffmap fit``: outputs, files, and one-line errors for bad input."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from helpers.cli_process import run_in_process as _cli

from stiffmap.errors import InputError
from stiffmap.models import PRR3, DeltaRobot, PoseError
from stiffmap.models.fit import static_error_predictions
from stiffmap.models.io import fit_measurements_file, read_measurements
from stiffmap.models.presets import paper48, prr3_points22


def test_model_3prr_json_default_points(monkeypatch, capsys):
    code, out, err = _cli(["model", "3prr", "--json"], monkeypatch, capsys)
    assert code == 0, err
    recs = json.loads(out)
    assert len(recs) == 22
    m = PRR3()
    P = prr3_points22()
    u = m.static_error(P, [0.0, 490.5])  # default load: 50 kgf along y
    K = m.stiffness(P)
    for i, r in enumerate(recs):
        assert set(r) == {"x", "y", "ux", "uy", "K", "det", "min_principal", "condition"}
        assert (r["x"], r["y"]) == tuple(P[i])
        np.testing.assert_allclose([r["ux"], r["uy"]], u[i], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(r["K"], K[i], rtol=1e-12)
        assert r["det"] == pytest.approx(np.linalg.det(K[i]), rel=1e-9)


def test_model_3prr_points_file_with_a_bad_point(monkeypatch, capsys, tmp_path):
    f = tmp_path / "pts.csv"
    f.write_text("x,y\n400,200\n400,900\n300,300\n")
    args = ["model", "3prr", "--points", f, "--load-n", "100", "--direction", "x", "--param", "kj=600"]
    code, out, err = _cli([*args, "--json"], monkeypatch, capsys)
    assert code == 1  # partial: one point could not be evaluated
    recs = json.loads(out)
    assert [("error" in r) for r in recs] == [False, True, False]
    assert recs[1]["error"].startswith("unreachable: ") and "off its rail" in recs[1]["error"]
    assert "1 of 3 point(s) cannot be evaluated" in err
    u = PRR3(kj=600.0).static_error([[400.0, 200.0], [300.0, 300.0]], [100.0, 0.0])
    np.testing.assert_allclose([[recs[i]["ux"], recs[i]["uy"]] for i in (0, 2)], u, rtol=1e-12)
    # CSV, written atomically to a file: same numbers, the reason in 'error'.
    o = tmp_path / "map.csv"
    code, out, err = _cli([*args, "--csv", "-o", o], monkeypatch, capsys)
    assert code == 1 and out == ""
    rows = list(csv.DictReader(io.StringIO(o.read_text())))
    assert rows[1]["error"].startswith("unreachable") and rows[1]["ux"] == ""
    assert float(rows[2]["ux"]) == pytest.approx(u[1, 0], rel=1e-8)


def test_model_delta_table_and_grid(monkeypatch, capsys):
    code, out, err = _cli(
        ["model", "delta", "--grid=-100:100:3,0,-310", "--direction", "0,1,0"], monkeypatch, capsys
    )
    assert code == 0, err
    assert "Delta R=150" in out and "F = (0, 4.905, 0) N" in out
    code, out, _ = _cli(["model", "delta", "--json"], monkeypatch, capsys)
    recs = json.loads(out)
    assert len(recs) == 48 and set(recs[0]) >= {"x", "y", "z", "ux", "uy", "uz", "K", "det", "min_principal"}
    u = DeltaRobot().static_error(paper48(), [0, 0, -4.905])
    np.testing.assert_allclose([[r["ux"], r["uy"], r["uz"]] for r in recs], u, rtol=1e-12)


@pytest.mark.parametrize(
    "args, message",
    [
        (["model", "3prr", "--param", "kj=-5"], "kj must be a positive number of N/mm, got -5.0"),
        (["model", "3prr", "--param", "L=0"], "L must be a positive number of mm"),
        (["model", "3prr", "--param", "kk=5"], "unknown 3prr parameter kk; valid: h, L, area, E, kj, kb"),
        (["model", "delta", "--param", "k_theta=abc"], "'abc' is not a number"),
        (["model", "3prr", "--direction", "z"], "--direction 'z': expected one of x, y, -x, -y"),
        (["model", "3prr", "--grid", "paper48"], "that preset is for the delta model"),
        (["model", "3prr", "--grid", "1:2"], "--grid '1:2': expected a preset (points22) or 2"),
        (["model", "delta", "--points", "/nonexistent/p.csv"], "/nonexistent/p.csv: file not found"),
        (["fit", "3prr", "/nonexistent/m.csv"], "/nonexistent/m.csv: file not found"),
        (["fit", "3prr", "x.csv", "--param-to-fit", "kjj"], "unknown 3prr parameter(s) kjj; valid: h, L"),
        (["model", "3prr", "--grid", "4000,9000", "--json"], "none of the 1 point(s) can be evaluated"),
    ],
)
def test_bad_input_is_one_line(monkeypatch, capsys, args, message):
    code, out, err = _cli(args, monkeypatch, capsys)
    assert code == 2
    assert message in err and err.startswith("error: ") and err.count("\n") == 1
    assert "Traceback" not in err


def test_bad_points_file_names_line_and_column(monkeypatch, capsys, tmp_path):
    f = tmp_path / "p.csv"
    f.write_text("x,y\n400,200\n400,abc\n")
    code, _, err = _cli(["model", "3prr", "--points", f], monkeypatch, capsys)
    assert code == 2 and "line 3, column 'y': 'abc' is not a number" in err


def _write_static_csv(path, model, rng, rel_noise=0.02, with_n=False):
    P = prr3_points22()
    pts = np.vstack([P, P])
    F = np.vstack([np.tile([490.5, 0.0], (22, 1)), np.tile([0.0, 490.5], (22, 1))])
    U = F / 490.5
    y = static_error_predictions(model, pts, F, U)
    std = rel_noise * np.abs(y)
    y = y + std * rng.standard_normal(y.size)
    cols = "x,y,fx,fy," + ("nx,ny," if with_n else "") + "value_mm,std_mm"
    lines = [cols]
    for i in range(y.size):
        nn = f"{U[i, 0]},{U[i, 1]}," if with_n else ""
        lines.append(f"{pts[i, 0]},{pts[i, 1]},{F[i, 0]},{F[i, 1]},{nn}{float(y[i])!r},{float(std[i])!r}")
    path.write_text("\n".join(lines) + "\n")
    return pts, F, U, y, std


def test_fit_command_static_errors(monkeypatch, capsys, tmp_path, rng):
    f = tmp_path / "static.csv"
    _write_static_csv(f, PRR3(), rng, with_n=True)
    code, out, err = _cli(["fit", "3prr", f, "--param", "kj=300", "--json"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    kj = d["parameters"]["kj"]
    assert kj["initial"] == 300.0 and abs(kj["estimate"] - 525.0) < 4 * kj["std"] and kj["std"] < 5.0
    assert d["n_observations"] == 44 and d["n_poses"] == 22 and d["kind"] == "static_error"
    code, out, err = _cli(
        ["fit", "3prr", f, "--param-to-fit", "kj", "--param-to-fit", "kb"], monkeypatch, capsys
    )
    assert code == 0, err
    assert "kj" in out and "kb" in out and "corr(kj, kb)" in out and "residual RMS per pose" in out
    code, out, err = _cli(["fit", "3prr", f, "--param-to-fit", "E,area"], monkeypatch, capsys)
    assert code == 2 and "cannot tell" in err and err.count("\n") == 1


def test_fit_file_stiffness_matrices_and_direction_default(tmp_path, rng):
    d = DeltaRobot()
    P = paper48()[::4]
    K = d.stiffness(P)
    s = 0.02 * np.abs(K).mean()
    Km = K + s * rng.standard_normal(K.shape)
    kc = [f"k{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
    rows = ["x,y,z," + ",".join(kc)] + [
        ",".join(repr(float(v)) for v in [*P[i], *Km[i].ravel()]) for i in range(P.shape[0])
    ]
    f = tmp_path / "K.csv"
    f.write_text("\n".join(rows) + "\n")
    fit, data = fit_measurements_file(d.with_params(k_theta=1e5), f, ["k_theta"])
    assert data.K_std is None and data.K.shape == (12, 3, 3)
    assert abs(fit.values["k_theta"] / d.k_theta - 1) < 4 * fit.std_values["k_theta"] / d.k_theta
    # Static errors without nx, ny: read along the force.
    g = tmp_path / "s.csv"
    g.write_text("x,y,fx,fy,value_mm\n400,200,0,-100,-0.2\n400,250,100,0,0.1\n")
    data = read_measurements(g, 2)
    np.testing.assert_allclose(data.directions, [[0, -1], [1, 0]])
    assert data.std is None


def test_measurement_file_errors_name_file_and_line(tmp_path):
    f = tmp_path / "m.csv"
    f.write_text("x,y,fx,fy,value_mm\n400,200,0,100,0.2\n400,900,0,100,0.3\n")
    with pytest.raises(
        PoseError, match=r"m.csv: line 3: pose \(400, 900\) mm cannot be evaluated .*unreachable"
    ):
        fit_measurements_file(PRR3(), f, ["kj"])
    f.write_text("x,y,fx,fy,nx,ny,value_mm\n400,200,0,100,0,2,0.2\n")
    with pytest.raises(InputError, match=r"line 2: the direction \(nx, ny\) has length 2"):
        read_measurements(f, 2)
    f.write_text("x,y,fx,fy,value_mm,std_mm\n400,200,0,100,0.2,-1\n")
    with pytest.raises(InputError, match=r"line 2, column 'std_mm': -1 is not a positive number"):
        read_measurements(f, 2)
    f.write_text("x,y,fx,fy,value_mm\n400,200,0,0,0.2\n")
    with pytest.raises(InputError, match="line 2: zero force and no nx, ny columns"):
        read_measurements(f, 2)
    f.write_text("x,y,dx\n1,2,3\n")
    with pytest.raises(InputError, match="cannot tell the kind of measurements"):
        read_measurements(f, 2)
    # A file for the other mechanism: named as such, not as an unreachable pose.
    f.write_text("x,y,z,fx,fy,fz,value_mm\n0,0,-300,0,0,-10,0.01\n")
    with pytest.raises(InputError, match=r"m.csv: columns 'z', 'fz' are 3-D, but this model is planar"):
        read_measurements(f, 2)
    f.write_text("x,y,k11,k12,k21,k22\n0,0,1,0,0,1\n")
    with pytest.raises(InputError, match=r"stop at k22 .* needs k11..k33"):
        read_measurements(f, 3)
    # Tab-separated, as the sensor recordings may be.
    f.write_text("x\ty\tfx\tfy\tvalue_mm\n400\t200\t0\t100\t0.2\n")
    assert read_measurements(f, 2).values.tolist() == [0.2]
