"""The simulated LDV/DAQ traces of the virtual test-bed (issue 4, item 4)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.sensor_traces import FAST_DAQ_CHAIN, FAST_LOAD_STEPS, quick_trace

from stiffmap.sim.traces import DaqChain, compliance_along, simulate_point_traces, simulate_trace


def test_signal_chain_scale_quantisation_saturation_and_load_resolution():
    """640 um/V, 16 bit over +-10 V (LSB 20/65536 V), clipping at +-8 V, dynamometer 0.05 kgf."""
    tr = quick_trace(1.0, seed=1)
    v = tr.recording.displacement_v
    lsb = 20.0 / 2**16
    assert np.all(np.abs(v / lsb - np.round(v / lsb)) < 1e-9)
    load = tr.recording.load
    assert np.all(np.abs(load / 0.05 - np.round(load / 0.05)) < 1e-9)
    # On the 50 kgf plateau the reading is 1000 um / 640 um/V = 1.5625 V (noise 1 um, drift small).
    a, b = tr.truth.plateaus_s[1]
    t = tr.recording.time_s
    m = (t > a + 0.2) & (t < b - 0.2)
    assert v[m].mean() == pytest.approx(1000.0 / 640.0, abs=5.0 / 640)
    assert tr.truth.static_error_mm == pytest.approx(1.0, rel=1e-12)
    assert tr.truth.loads_n == pytest.approx([0, 490.5, 392.4, 294.3, 196.2, 98.1, 0], abs=1e-9)
    # Beyond the range the LDV clips at 8 V, quantised to the last DAQ code below it.
    big = quick_trace(6.0, seed=1, chain=DaqChain(sample_rate_hz=500.0, noise_um=0.0, drift_wander_um=0.0))
    assert big.recording.displacement_v.max() == pytest.approx(8.0, abs=lsb)
    noq = quick_trace(1.0, seed=1, chain=DaqChain(sample_rate_hz=500.0, daq_bits=0))
    assert (
        np.mean(np.abs(noq.recording.displacement_v / lsb - np.round(noq.recording.displacement_v / lsb)))
        > 0.1
    )


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    truths = []
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        truths.append(
            simulate_point_traces(tmp_path / name, [[0.0, 500.0]], [[0.0, 1.0]], 2e-3, seed=seed, fmt="tdms")
        )
    a = (tmp_path / "a" / "trace_000.tdms").read_bytes()
    assert a == (tmp_path / "b" / "trace_000.tdms").read_bytes()
    assert a != (tmp_path / "c" / "trace_000.tdms").read_bytes()
    assert (tmp_path / "a" / "truth.json").read_bytes() == (tmp_path / "b" / "truth.json").read_bytes()


def test_compliance_from_a_number_a_callable_or_a_mechanism():
    p, u = np.array([10.0, 500.0]), np.array([0.0, 1.0])

    class Spring2D:
        """A mechanism-like object: static_error(points, force) = C f, C = diag(1/500, 1/800) mm/N."""

        def static_error(self, points, force):
            C = np.diag([1 / 500, 1 / 800])
            return (C @ np.asarray(force, dtype=float))[None, :].repeat(len(points), axis=0)

    assert compliance_along(2e-3, p, u) == 2e-3
    assert compliance_along(lambda q: 1e-6 * q[1], p, u) == pytest.approx(5e-4, rel=1e-15)
    assert compliance_along(lambda q, d: 1e-3 * (1 + d[0]), p, u) == pytest.approx(1e-3, rel=1e-15)
    assert compliance_along(Spring2D(), p, u) == pytest.approx(1 / 800, rel=1e-15)
    assert compliance_along(Spring2D(), p, np.array([1.0, 0.0])) == pytest.approx(1 / 500, rel=1e-15)
    with pytest.raises(TypeError, match="compliance must be"):
        compliance_along("stiff", p, u)


def test_point_traces_index_and_truth(tmp_path):
    pts = [[0.0, 400.0], [0.0, 450.0]]
    dirs = [[2.0, 0.0], [0.0, 1.0]]  # normalised inside
    truths = simulate_point_traces(
        tmp_path,
        pts,
        dirs,
        lambda q: 1e-6 * q[1],
        axis_signs=[-1, 1],
        chain=FAST_DAQ_CHAIN,
        protocol=FAST_LOAD_STEPS,
    )
    assert [t.static_error_mm for t in truths] == pytest.approx([0.4 * 490.5e-3, 0.45 * 490.5e-3], rel=1e-12)
    idx = (tmp_path / "index.csv").read_text().splitlines()
    assert idx[0] == "x,y,ux,uy,file,axis_sign"
    assert idx[1] == "0,400,1,0,trace_000.csv,-1"
    tj = json.loads((tmp_path / "truth.json").read_text())
    assert tj["traces"][1]["static_error_um"] == pytest.approx(0.45 * 490.5, rel=1e-12)
    assert tj["traces"][0]["axis_sign"] == -1
    with pytest.raises(ValueError, match="non-zero vector"):
        simulate_point_traces(tmp_path, pts, [[0.0, 0.0], [0, 1]], 1e-3)


def test_simulate_trace_checks_its_arguments():
    with pytest.raises(ValueError, match="exactly one of"):
        simulate_trace(1e-3, static_error_mm=0.5)
    with pytest.raises(ValueError, match="axis_sign"):
        simulate_trace(1e-3, axis_sign=0)
    with pytest.raises(ValueError, match="noise_um must be >= 0"):
        DaqChain(noise_um=-1)
