"""Exports derived from a campaign's database: CSV and Parquet tables, a JSON summary.

Written to ``CAMPAIGN/exports/`` atomically; they are always recomputed from
``stiffmap.db`` and never read back.

Tables (one row each):

- ``stiffness``: per position x, y, z (mm), status, K entries ``k11..k33`` and
  standard errors ``s11..s33`` (N/mm), det (N/mm)^3, smallest principal
  stiffness and the three principal stiffnesses (N/mm), condition numbers,
  the camera calibration's share of the variance of k11, k22, k33 (``cal_share_k11``...,
  0..1; empty when camera.json gives no uncertainty), flags (joined by " | ");
- ``displacements``: per position, load case and repeat: dx, dy, dz (mm),
  rx, ry, rz (rad) in the base frame, their propagated standard deviations
  (the calibration's share included) and the calibration's share of the variance
  of dx, dy, dz (``cal_share_dx``...);
- ``repeat_stats``: per position, load case and quantity: mean, std, n;
- ``measurements``: per image: status, error, reprojection RMS (px), corners, tracked, and with
  several cameras what each gave (``cameras``: its RMS or its error);
- ``model_stiffness``: the model's K at every position (when a model is given);
- ``sensor_results``: per recording the point (mm), direction, static error and its
  standard error (um), stiffness (N/mm), the model's static error (um), flags.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..io import atomic_write_bytes, atomic_write_text, dumps_json
from .store import Store

__all__ = ["export_tables", "summary_dict", "read_tables", "calibration_share_of_K"]

_IJ = [(i, j) for i in range(3) for j in range(3)]


def _share(cov_part: np.ndarray | None, cov: np.ndarray | None) -> np.ndarray:
    """Share of each diagonal variance of ``cov`` that ``cov_part`` holds (NaN: unknown)."""
    if cov_part is None or cov is None:
        return np.full(36, np.nan)
    tot = np.diag(cov)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(tot > 0, np.diag(cov_part) / tot, np.nan)


def _std_matrix(cov: np.ndarray | None) -> np.ndarray | None:
    """The (3, 3) standard deviations of a (9, 9) covariance of K.ravel(), or None."""
    return None if cov is None else np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(3, 3)


def calibration_share_of_K(store: Store) -> tuple[float, float] | None:
    """Median and largest share of the camera calibration in the variance of k11, k22, k33 over
    the positions (0..1); None when no position carries it (camera.json without uncertainty)."""
    shares = []
    for r in store.stiffness_rows():
        sh = _share(r.K_cov_calibration, r.K_cov)
        if r.status == "ok" and np.all(np.isfinite(sh[[0, 4, 8]])):
            shares.extend(sh[[0, 4, 8]])
    return (float(np.median(shares)), float(np.max(shares))) if shares else None


def _num(x: float) -> float | None:
    return None if not np.isfinite(x) else float(x)


def read_tables(store: Store) -> dict[str, list[dict[str, Any]]]:
    """The export tables as lists of flat dicts (numbers, strings, None)."""
    out: dict[str, list[dict[str, Any]]] = {}
    out["stiffness"] = _stiffness_table(store)
    out["displacements"] = _displacement_table(store)
    out["repeat_stats"] = [dataclasses.asdict(r) for r in store.repeat_stat_rows()]
    out["measurements"] = _measurement_table(store)
    out["model_stiffness"] = _model_stiffness_table(store)
    out["sensor_results"] = _sensor_table(store)
    return out


def _stiffness_table(store: Store) -> list[dict[str, Any]]:
    """One row per position: K, its standard errors, principal stiffnesses, conditions, the
    calibration's share and flags."""
    rows = []
    for r in store.stiffness_rows():
        K = r.K
        S = r.K_std
        share_K = _share(r.K_cov_calibration, r.K_cov)
        eig = r.eigenvalues
        flags = r.flags or []
        row: dict[str, Any] = {
            "position": r.position,
            "x_mm": r.x,
            "y_mm": r.y,
            "z_mm": r.z,
            "status": r.status,
            "error": r.error,
            "method": r.method,
        }
        for i, j in _IJ:
            row[f"k{i + 1}{j + 1}_n_per_mm"] = None if K is None else float(K[i, j])
        for i, j in _IJ:
            row[f"s{i + 1}{j + 1}_n_per_mm"] = None if S is None else float(S[i, j])
        row.update(
            det=r.det,
            min_principal_n_per_mm=r.min_principal,
            **{f"principal{k + 1}_n_per_mm": (None if eig is None else float(eig[k])) for k in range(3)},
            K_condition=r.K_condition,
            design_condition=r.design_condition,
            n_obs=r.n_obs,
            **{f"cal_share_k{k + 1}{k + 1}": _num(share_K[4 * k]) for k in range(3)},
            flags=" | ".join(flags),
        )
        rows.append(row)
    return rows


def _displacement_table(store: Store) -> list[dict[str, Any]]:
    """One row per displacement measured: its 6 components, their standard deviations and the
    calibration's share."""
    rows = []
    for r in store.displacement_rows():
        d = r.d if r.d is not None else np.full(6, np.nan)
        cov = r.cov if r.cov is not None else np.full((6, 6), np.nan)
        s = np.sqrt(np.clip(np.diag(cov), 0, None))
        share_d = _share(r.cov_calibration, cov)
        row = {"position": r.position, "load": r.load, "repeat": r.repeat, "frame": r.frame}
        for k, name in enumerate(("dx_mm", "dy_mm", "dz_mm", "rx_rad", "ry_rad", "rz_rad")):
            row[name] = None if np.isnan(d[k]) else float(d[k])
        for k, name in enumerate(("sx_mm", "sy_mm", "sz_mm", "srx_rad", "sry_rad", "srz_rad")):
            row[name] = None if np.isnan(s[k]) else float(s[k])
        for k, name in enumerate(("cal_share_dx", "cal_share_dy", "cal_share_dz")):
            row[name] = _num(share_d[k])
        row.update(status=r.status, error=r.error, unloaded=r.unloaded, loaded=r.loaded)
        rows.append(row)
    return rows


def _measurement_table(store: Store) -> list[dict[str, Any]]:
    """One row per image measured: its status, error, residual and cameras."""
    return [
        {
            "image": r.image,
            "position": r.position,
            "status": r.status,
            "error": r.error,
            "rms_px": r.rms_px,
            "n_corners": r.n_corners,
            "tracked": bool(r.tracked) if r.tracked is not None else None,
            "cameras": _cameras_text(r.per_camera),
        }
        for r in store.measurement_rows()
    ]


def _model_stiffness_table(store: Store) -> list[dict[str, Any]]:
    """One row per position and model: the model's K."""
    rows = []
    for r in store.model_stiffness_rows():
        K = r.K
        row = {
            "position": r.position,
            "model": r.model,
            "valid": bool(r.valid),
            "reason": r.reason,
        }
        for i, j in _IJ:
            row[f"k{i + 1}{j + 1}_n_per_mm"] = None if K is None else float(K[i, j])
        row.update(det=r.det, min_principal_n_per_mm=r.min_principal)
        rows.append(row)
    return rows


def _sensor_table(store: Store) -> list[dict[str, Any]]:
    """One row per sensor recording: its static error, stiffness and the model's static error."""
    pred = store.model_static_errors()
    rows = []
    for r in store.sensor_result_rows():
        res = r.result or {}
        pt = r.point or []
        predicted = pred.get(r.recording)
        rows.append(
            {
                "file": r.recording,
                **{f"{a}_mm": (pt[k] if k < len(pt) else None) for k, a in enumerate("xyz")},
                "direction": r.direction,
                "status": r.status,
                "error": r.error,
                "static_error_um": res.get("static_error_um"),
                "static_error_std_um": res.get("static_error_std_um"),
                "stiffness_n_per_mm": res.get("stiffness_n_per_mm"),
                "stiffness_std_n_per_mm": res.get("stiffness_std_n_per_mm"),
                "model_static_error_um": None if predicted is None else 1e3 * predicted,
                "flags": " | ".join(res.get("flags", [])),
            }
        )
    return rows


def _csv_bytes(rows: list[dict[str, Any]]) -> bytes:
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue().encode("utf-8")


def _parquet_bytes(rows: list[dict[str, Any]]) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist(rows) if rows else pa.table({})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


def summary_dict(store: Store, name: str, failures: list[str], notes=()) -> dict[str, Any]:
    """The JSON summary: per position K, det, smallest principal stiffness, flags; the model fit;
    the failures and the notes (what a fit accounted for: ``RunSummary.info``)."""
    positions = []
    for r in store.stiffness_rows():
        positions.append(
            {
                "position": r.position,
                "xyz_mm": [r.x, r.y, r.z],
                "status": r.status,
                "error": r.error,
                "K": r.K,
                "K_std": r.K_std,
                "K_std_calibration": _std_matrix(r.K_cov_calibration),
                "det": r.det,
                "min_principal": r.min_principal,
                "flags": r.flags or [],
            }
        )
    fits = []
    for r in store.model_fit_rows():
        fits.append(
            {
                "name": r.name,
                "model": r.model,
                "status": r.status,
                "error": r.error,
                "params": r.params,
                "std": r.std,
                "condition": r.condition,
            }
        )
    sensors = [
        {k: v for k, v in r.items() if k not in ("flags",)} for r in read_tables(store)["sensor_results"]
    ]
    return {
        "campaign": name,
        "stiffmap_version": __version__,
        "positions": positions,
        "sensor_results": sensors,
        "model_fits": fits,
        "failures": failures,
        "notes": list(notes),
    }


def export_tables(store: Store, out_dir: str | Path, name: str, failures: list[str], notes=()) -> list[Path]:
    """Write every table as CSV and Parquet, and ``summary.json``; return the paths written."""
    out = Path(out_dir)
    written = []
    for table, rows in read_tables(store).items():
        for ext, data in (("csv", _csv_bytes(rows)), ("parquet", _parquet_bytes(rows))):
            p = out / f"{table}.{ext}"
            atomic_write_bytes(p, data)
            written.append(p)
    p = out / "summary.json"
    atomic_write_text(p, dumps_json(summary_dict(store, name, failures, notes)) + "\n")
    written.append(p)
    return written


def _cameras_text(per: list | None) -> str | None:
    """With several cameras, what each gave for an image set: ``cam1: 0.031 px; cam2: <its error>``."""
    if not isinstance(per, list):
        return None
    parts = []
    for c in per:
        if not isinstance(c, dict):
            continue
        rms = c.get("rms_px")
        what = f"{rms:.3f} px" if isinstance(rms, (int, float)) else "no board"
        if c.get("error"):
            what += f" ({c['error']})"
        parts.append(f"{c.get('name')}: {what}")
    return "; ".join(parts)
