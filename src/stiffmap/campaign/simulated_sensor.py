"""Write a simulated sensor campaign (the 3PRR measured by an LDV) with its ground truth.

The milling study's test-bed in software: at each point the tool is loaded in steps
(0, 50, 40, 30, 20, 10, 0 kgf) along x and along y, and a laser Doppler vibrometer
behind a DAQ records the tool's displacement along the load; horizontal (x)
recordings go through a mirror (axis sign -1), as in the study's Fig. 4. The
recordings themselves come from :mod:`stiffmap.sim.traces`
(:func:`~stiffmap.sim.traces.simulate_point_traces`); this module lays them out
as a campaign that ``stiffmap run`` reads::

    OUT_DIR/
      campaign.toml            # kind = "sensor", [robot] 3prr and its parameters, [sensor] recordings
      recordings/trace_000.csv, ...   # one per point x direction x repeat (+ index.csv, truth.json)
      truth.json               # K (2x2) and the static error at the reference load per point
      .stiffmap-simulation     # marker (see stiffmap.campaign.truth)
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import FieldError, InputError
from ..io import atomic_write_text, to_jsonable
from ..models.base import PoseError
from ..sim.traces import simulate_point_traces
from ..units import G_REFERENCE_PAPER
from .simulated import prepare_output_dir
from .spec import CampaignSpec
from .spec_writer import dump_spec
from .truth import TRUTH_FORMAT, TRUTH_NAME, compact_json

__all__ = ["SensorSimSummary", "write_sensor_campaign"]

_AXES = {"x": (1.0, 0.0), "y": (0.0, 1.0)}


@dataclass(frozen=True)
class SensorSimSummary:
    """What :func:`write_sensor_campaign` wrote."""

    out_dir: Path
    n_points: int
    directions: tuple[str, ...]
    repeats: int
    n_recordings: int
    bytes_written: int
    seconds: float
    static_error_range_mm: tuple[float, float]
    #: The robot model's name and its finite parameters, and the recordings' format.
    robot: str = ""
    params: dict[str, float] = field(default_factory=dict)
    format: str = "csv"


def write_sensor_campaign(
    out_dir: str | os.PathLike,
    model,
    points,
    *,
    directions: tuple[str, ...] = ("x", "y"),
    repeats: int = 1,
    seed: int = 0,
    fmt: str = "csv",
    force: bool = False,
    reference_load_n: float = 490.5,
    name: str = "virtual test-bed (3PRR, LDV)",
    command: str = "",
) -> SensorSimSummary:
    """Simulate LDV recordings of a planar mechanism and write the sensor campaign.

    Parameters
    ----------
    out_dir : path-like
        New or empty directory (or a previous simulation, with ``force``).
    model : mechanism
        A planar model with ``static_error(points, force)``, ``stiffness(points)`` and
        ``params()`` (:class:`stiffmap.models.prr3.PRR3`).
    points : array_like, shape (m, 2), mm
    directions : tuple of {"x", "y"}
        Load and measurement directions at every point.
    repeats : int
        Recordings per point and direction.
    seed : int
        Recording i uses the seed sequence (seed, i): reproducible bit for bit.
    fmt : {"csv", "tdms", "mat"}
    reference_load_n : float
        Load at which the static error is reported, N (the study's 50 kgf).

    Raises
    ------
    InputError
        Output directory not usable; a point where the model has no stiffness (named).
    """
    t0 = time.perf_counter()
    P, dirs = _checked_inputs(points, directions, repeats, fmt)
    K = _stiffness_at(model, P)
    out = Path(out_dir)
    prepare_output_dir(out, force)
    truths, recordings = _simulate_recordings(out, model, P, dirs, int(repeats), fmt, seed, reference_load_n)
    params = {k: float(v) for k, v in model.params().items() if math.isfinite(v)}
    spec = _sensor_spec(name, int(repeats), model.name, params, float(reference_load_n), recordings)
    header = (
        f"Simulated by 'stiffmap simulate --robot {model.name}' (stiffmap {__version__}, seed {seed}).\n"
        f"The ground truth (K and the static error at every point) is in {TRUTH_NAME}."
    )
    atomic_write_text(out / "campaign.toml", dump_spec(spec, header))
    positions = _true_positions(P, K, dirs, reference_load_n)
    truth = _truth(model.name, params, int(seed), command, float(reference_load_n), positions, truths)
    atomic_write_text(out / TRUTH_NAME, compact_json(to_jsonable(truth)) + "\n")
    se = [abs(t.static_error_mm) for t in truths]
    size = sum(f.stat().st_size for f in (out / "recordings").iterdir() if f.is_file())
    return SensorSimSummary(
        out_dir=out,
        n_points=len(P),
        directions=dirs,
        repeats=int(repeats),
        n_recordings=len(truths),
        bytes_written=int(size),
        seconds=time.perf_counter() - t0,
        static_error_range_mm=(float(min(se)), float(max(se))),
        robot=model.name,
        params=params,
        format=fmt,
    )


def _checked_inputs(points, directions, repeats, fmt: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """The points as an (m, 2) array (mm) and the directions as distinct 'x'/'y'; repeats, format checked."""
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 2 or P.shape[0] == 0 or not np.all(np.isfinite(P)):
        raise InputError(f"a planar mechanism needs points (x, y) in mm; got an array of shape {P.shape}")
    dirs = tuple(d.strip().lower() for d in directions)
    if not dirs or any(d not in _AXES for d in dirs) or len(set(dirs)) != len(dirs):
        raise FieldError("directions", f"must be x and/or y, got {directions!r}", value=directions)
    if int(repeats) < 1:
        raise InputError(f"repeats must be >= 1, got {repeats}")
    if fmt not in ("csv", "tdms", "mat"):
        raise InputError(f"recording format must be csv, tdms or mat, got {fmt!r}")
    return P, dirs


def _stiffness_at(model, P: np.ndarray) -> np.ndarray:
    """The model's 2x2 stiffness at each point, shape (m, 2, 2), N/mm; a point without one named."""
    try:
        return np.asarray(model.stiffness(P), dtype=np.float64).reshape(-1, 2, 2)
    except PoseError as e:
        if e.index is None:
            raise
        p = P[e.index]
        raise InputError(
            f"position {e.index + 1} ({p[0]:g}, {p[1]:g}) mm: the robot model has no stiffness there "
            f"({e.reason or e.detail})",
            items={"position": e.index + 1},
        ) from None


def _simulate_recordings(out: Path, model, P, dirs, repeats: int, fmt: str, seed, reference_load_n):
    """Write one recording per point x direction x repeat (x through a mirror: sign -1).

    Returns
    -------
    truths : list of the recordings' truths (:func:`~stiffmap.sim.traces.simulate_point_traces`)
    recordings : list of dict
        campaign.toml's ``[[sensor.recordings]]``: point, direction, file, sign.
    """
    rows = [(i, d, r) for i in range(len(P)) for d in dirs for r in range(1, repeats + 1)]
    pts = np.array([P[i] for i, _, _ in rows])
    U = np.array([_AXES[d] for _, d, _ in rows])
    signs = np.array([-1 if d == "x" else 1 for _, d, _ in rows])
    truths = simulate_point_traces(
        out / "recordings",
        pts,
        U,
        model,
        fmt=fmt,
        axis_signs=signs,
        g=G_REFERENCE_PAPER,
        reference_load_n=reference_load_n,
        seed=int(seed),
    )
    recordings = [
        {
            "point": [float(v) for v in pts[k]],
            "direction": rows[k][1],
            "file": f"recordings/{t.file}",
            "sign": int(signs[k]),
        }
        for k, t in enumerate(truths)
    ]
    return truths, recordings


def _sensor_spec(
    name: str, repeats: int, model_name: str, params: dict, reference_load_n: float, recordings: list[dict]
) -> CampaignSpec:
    """campaign.toml of the simulated campaign: the LDV chain of the milling study, loads in kgf."""
    return CampaignSpec.model_validate(
        {
            "name": name,
            "kind": "sensor",
            "g": G_REFERENCE_PAPER,
            "repeats": repeats,
            "robot": {"model": model_name, "params": params},
            "sensor": {
                "scale_um_per_v": 640.0,
                "range_v": 8.0,
                "load_unit": "kgf",
                "reference_load_n": reference_load_n,
                "recordings": recordings,
            },
        }
    )


def _true_positions(P: np.ndarray, K: np.ndarray, dirs, reference_load_n: float) -> list[dict]:
    """truth.json's positions: K, det K and the static error along each direction, mm."""
    positions = []
    for i, p in enumerate(P):
        e = {"index": i + 1, "position": p, "K": K[i], "det": float(np.linalg.det(K[i]))}
        for d in dirs:
            u = np.asarray(_AXES[d])
            e[f"static_error_{d}_mm"] = float(u @ np.linalg.solve(K[i], reference_load_n * u))
        positions.append(e)
    return positions


def _truth(
    model_name: str, params: dict, seed: int, command: str, reference_load_n: float, positions, truths
) -> dict:
    """truth.json of the simulated sensor campaign (K and static errors per point, each recording)."""
    return {
        "format": TRUTH_FORMAT,
        "kind": "sensor",
        "generator": {"tool": "stiffmap simulate", "version": __version__, "command": command},
        "seed": seed,
        "units": "mm, N; K in N/mm (2x2, planar); static errors at reference_load_n along the load",
        "robot": {"model": model_name, "params": params},
        "reference_load_n": reference_load_n,
        "positions": positions,
        "recordings": [{**t.to_dict(), "file": f"recordings/{t.file}"} for t in truths],
    }
