"""``stiffmap run`` on a sensor campaign: recordings -> static errors -> model fit.

Each recording of ``[sensor]`` (a point, a load direction, a file) is analysed
(:func:`stiffmap.sensors.analysis.analyse_recording`) and its result stored in
``sensor_results`` in its own transaction, keyed by the file and its SHA-256: an
unchanged recording is not analysed again. When the campaign names a model
(``robot.model = "3prr"``), its parameters (``robot.fit``, default ``kj``) are
fitted to the measured static errors (:func:`stiffmap.models.fit.fit_static_errors`)
and the fitted model's static errors are stored beside the measured ones.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..errors import FieldError, InputError
from ..models.fit import fit_static_errors, separation_notes
from ..sensors.analysis import SensorConfig, analyse_recording
from ..sensors.batch import direction_from
from ..sensors.io import read_recording
from ..sensors.recording import ChannelMap, parse_channel_map
from .fingerprint import robot_fingerprint
from .paths import campaign_file
from .robot import fitted_names, robot_model
from .spec import SPEC_NAME, CampaignSpec, SensorRecordingSpec
from .store import Store, model_fit_columns, params_hash, to_json

__all__ = ["run_sensor_campaign", "check_recording_paths", "sensor_config", "SensorCampaignResult"]


def sensor_config(spec: CampaignSpec) -> tuple[SensorConfig, ChannelMap]:
    """The :class:`~stiffmap.sensors.analysis.SensorConfig` and channel map of a sensor campaign."""
    s = spec.sensor
    cmap = parse_channel_map(",".join(f"{k}={v}" for k, v in s.channel_map.items()) or None)
    steps, unit = (s.steps_n, "N") if s.steps_n is not None else (s.steps_kgf, "kgf")
    cfg = SensorConfig(
        scale_um_per_v=s.scale_um_per_v,
        range_v=s.range_v,
        load_unit=s.load_unit,
        load_n_per_v=s.load_n_per_v,
        steps=tuple(steps) if steps is not None else None,
        steps_unit=unit,
        g=spec.g,
        reference_load_n=s.reference_load_n,
        window_s=s.window_s,
        min_plateau_s=s.min_plateau_s,
        threshold_sigma=s.threshold_sigma,
        remove_drift=s.remove_drift,
        exclude_bad_samples=s.exclude_bad_samples,
    )
    return cfg, cmap


@dataclass
class SensorCampaignResult:
    """What a sensor campaign run did."""

    campaign: str
    recordings: int = 0
    analysed: int = 0
    reused: int = 0
    wall_seconds: float = 0.0
    failures: list[str] | None = None


def run_sensor_campaign(
    root: Path, spec: CampaignSpec, store: Store, *, allow_outside: bool = False
) -> SensorCampaignResult:
    """Analyse every recording (reusing unchanged ones) and fit the model.

    Raises
    ------
    InputError
        A recording's file name leads outside the campaign directory and not
        ``allow_outside`` (:mod:`stiffmap.campaign.paths`).
    """
    t0 = time.perf_counter()
    check_recording_paths(root, spec, allow_outside=allow_outside)
    try:
        cfg, cmap = sensor_config(spec)
    except ValueError as e:  # the spec checks these; a settings' check of the analysis says more
        if isinstance(e, InputError) and e.source:
            raise
        raise InputError(f"key 'sensor': {e}", source=str(root / SPEC_NAME)) from None
    phash = params_hash({"config": dataclasses.asdict(cfg), "channels": dataclasses.asdict(cmap)})
    out = SensorCampaignResult(campaign=spec.name, recordings=len(spec.sensor.recordings), failures=[])
    # Recordings no longer in campaign.toml leave the results.
    store.delete_recordings_not_in([rec.file for rec in spec.sensor.recordings])
    for i, rec in enumerate(spec.sensor.recordings):
        _analyse_or_reuse(root, store, rec, i, cfg, cmap, phash, out)
    out.failures.extend(_fit_model(spec, store, root))
    out.wall_seconds = time.perf_counter() - t0
    return out


def check_recording_paths(root: Path, spec: CampaignSpec, *, allow_outside: bool = False) -> None:
    """InputError when a recording's file name leads outside the campaign directory (and not
    ``allow_outside``), naming its key (:func:`stiffmap.campaign.paths.campaign_file`)."""
    for i, rec in enumerate(spec.sensor.recordings):
        campaign_file(root, rec.file, f"sensor.recordings[{i}].file", allow_outside=allow_outside)


def spec_keys(index: int) -> dict[str, str]:
    """The analysis' fields as the campaign.toml keys that set them (recording ``index``'s own)."""
    keys = {
        f: f"sensor.{f}"
        for f in (
            "scale_um_per_v",
            "range_v",
            "load_unit",
            "load_n_per_v",
            "reference_load_n",
            "window_s",
            "min_plateau_s",
            "threshold_sigma",
            "exclude_bad_samples",
            "channel_map",
        )
    }
    keys.update(
        steps="sensor.steps_kgf (or steps_n)",
        step_times_s=f"sensor.recordings[{index}].step_times",
        axis_sign=f"sensor.recordings[{index}].sign",
        g="g",
    )
    return keys


def _analyse_or_reuse(
    root: Path,
    store: Store,
    rec: SensorRecordingSpec,
    index: int,
    cfg: SensorConfig,
    cmap: ChannelMap,
    phash: str,
    out: SensorCampaignResult,
) -> None:
    """Analyse one recording and store its result, unless the stored one is of the same file and settings."""
    path = root / rec.file
    key = rec.file
    rhash = params_hash({"analysis": phash, "sign": rec.sign, "step_times": rec.step_times})
    row: dict[str, Any] = {
        "recording": key,
        "point": to_json(rec.point),
        "direction": rec.direction,
        "params_hash": rhash,
        "version": __version__,
    }
    if not path.is_file():
        why = "is a folder, not a recording" if path.is_dir() else "file not found"
        why += f" (sensor.recordings[{index}].file in campaign.toml)"
        store.save_sensor_result({**row, "sha256": None, "status": "failed", "error": why})
        out.failures.append(f"{key}: {why}")
        return
    sha = store.sha256(path)
    prev = store.sensor_result(key)
    if prev is not None and prev.sha256 == sha and prev.params_hash == rhash:
        out.reused += 1
        if (to_json(prev.point), prev.direction) != (row["point"], row["direction"]):
            # Where it was measured has been corrected.
            store.set_recording_place(key, row["point"], row["direction"])
        if prev.status != "ok":
            out.failures.append(prev.error)
        return
    try:
        c = dataclasses.replace(
            cfg,
            axis_sign=rec.sign,
            step_times_s=tuple(tuple(span) for span in rec.step_times) if rec.step_times else None,
        )
    except FieldError as e:  # the spec checks these; a settings' check of the analysis says more
        raise e.worded(spec_keys(index)).with_source(str(root / SPEC_NAME)) from None
    except ValueError as e:
        raise InputError(f"key 'sensor.recordings[{index}]': {e}", source=str(root / SPEC_NAME)) from None
    try:
        res = analyse_recording(read_recording(path, cmap), c)
        result = res.to_dict()
        result["static_error_mm"] = res.static_error_mm
        result["static_error_std_mm"] = res.static_error_std_mm
        status, error = "ok", None
    except FieldError as e:  # a setting the recording contradicts: named by its campaign.toml key
        result, status, error = None, "failed", str(e.worded(spec_keys(index)).with_source(key))
        out.failures.append(error)
    except InputError as e:
        result, status, error = None, "failed", str(e.with_source(key))
        out.failures.append(error)
    store.save_sensor_result(
        {**row, "sha256": sha, "status": status, "error": error, "result": to_json(result)}
    )
    out.analysed += 1


def measured_static_errors(spec: CampaignSpec, store: Store) -> dict[str, np.ndarray]:
    """Measured static errors of the campaign's recordings, in spec order.

    Returns
    -------
    dict
        ``points`` (m, d) mm, ``directions`` (m, d) unit, ``value_mm``, ``std_mm`` (m,)
        (NaN where the recording failed), ``valid`` (m,) bool, ``files`` list.
    """
    recs = spec.sensor.recordings
    d = max(len(r.point) for r in recs)
    pts = np.array([list(r.point) + [0.0] * (d - len(r.point)) for r in recs], dtype=float)
    dirs = np.stack([direction_from(r.direction, d) for r in recs])
    vals = np.full(len(recs), np.nan)
    stds = np.full(len(recs), np.nan)
    stiff = np.full(len(recs), np.nan)
    flags: list[list[str]] = [[] for _ in recs]
    rows = {r.recording: r for r in store.sensor_result_rows()}
    for i, r in enumerate(recs):
        row = rows.get(r.file)
        if row is not None and row.status == "ok":
            res = row.result
            vals[i] = res["static_error_mm"]
            stds[i] = res["static_error_std_mm"] if res["static_error_std_mm"] is not None else np.nan
            k = res.get("stiffness_n_per_mm")
            stiff[i] = k if k is not None else np.nan
            flags[i] = list(res.get("flags") or [])
    return {
        "points": pts,
        "directions": dirs,
        "value_mm": vals,
        "std_mm": stds,
        "valid": np.isfinite(vals),
        "stiffness_n_per_mm": stiff,
        "flags": flags,
        "files": [r.file for r in recs],
        "reference_load_n": spec.sensor.reference_load_n,
    }


def _fit_model(spec: CampaignSpec, store: Store, root: Path) -> list[str]:
    """Fit the campaign's model to the measured static errors; store the fit and its static errors."""
    name = spec.robot.model
    if spec.robot.kind is None:
        return []
    problems: list[str] = []
    m = measured_static_errors(spec, store)
    try:
        model = robot_model(spec.robot, root)
        fit_names = fitted_names(spec, model)
    except InputError as e:  # it names the file or the key
        return [f"robot model: {e}"]
    except ValueError as e:
        return [f"campaign.toml robot.params: {e}"]
    if m["points"].shape[1] != model.dim:
        n = m["points"].shape[1]
        return [f"campaign.toml: sensor points have {n} coordinates but the {name} model has {model.dim}"]
    v = m["valid"]
    ihash = params_hash(
        {
            "model": name,
            "params": spec.robot.params,
            "fit": fit_names,
            "points": m["points"],
            "directions": m["directions"],
            "values": m["value_mm"],
        }
    )
    row: dict[str, Any] = {
        "name": "static_error",
        "model": name,
        "inputs_hash": ihash,
        "version": __version__,
        "robot": to_json(robot_fingerprint(spec, root)),
    }
    fitted = model
    negative = v & (m["stiffness_n_per_mm"] < 0)
    for i in np.flatnonzero(negative):
        problems.append(
            f"recording {m['files'][i]}: negative stiffness (the displacement goes against the load): "
            "left out of the model fit; check its sign (sign = -1 behind a mirror) and direction"
        )
    reach = model.evaluate(m["points"]).valid
    v = v & ~negative & reach  # unreachable points are named below
    fitted = _fit_static(model, m, v, fit_names, row, problems)
    _save_static_errors(store, fitted, m, row, name, ihash, problems)
    return problems


def _fit_static(model, m: dict, v: np.ndarray, fit_names, row: dict[str, Any], problems: list[str]):
    """The model fitted to the usable recordings ``v`` (``model`` itself when the fit fails: the
    failure in ``row`` and ``problems``); the fit's columns in ``row``."""
    ref = m["reference_load_n"]
    fitted = model
    try:
        if v.sum() == 0:
            raise InputError("no usable recording to fit")
        std = m["std_mm"][v]
        fit = fit_static_errors(
            model,
            m["points"][v],
            ref * m["directions"][v],
            m["directions"][v],
            m["value_mm"][v],
            params=fit_names,
            std=std if np.all(np.isfinite(std)) else None,
        )
        fitted = fit.model
        row.update(model_fit_columns(fit, fit.residuals))
        problems.extend(
            f"model fit: {n}" for n in separation_notes(fit.names, fit.estimate, fit.std, fit.correlation)
        )
    except (InputError, ValueError) as e:
        row.update(status="failed", error=str(e))
        problems.append(f"model fit: {e}")
    return fitted


def _save_static_errors(
    store: Store, fitted, m: dict, row: dict[str, Any], name: str, ihash: str, problems: list[str]
) -> None:
    """Store the fit ``row`` and the fitted model's static error along each measured direction,
    and its reach (a recording outside it appended to ``problems``)."""
    ref = m["reference_load_n"]
    mm = fitted.evaluate(m["points"])
    pred = np.einsum("ij,ij->i", mm.static_error(ref * m["directions"]), m["directions"])
    store.save_model_static_errors(
        row,
        [
            {
                "recording": f,
                "model": name,
                "valid": int(bool(mm.valid[i])),
                "reason": mm.reasons[i] or None,
                "predicted_mm": float(pred[i]) if mm.valid[i] else None,
                "inputs_hash": ihash,
            }
            for i, f in enumerate(m["files"])
        ],
    )
    for i, f in enumerate(m["files"]):
        if not mm.valid[i]:
            problems.append(
                f"recording {f}: point {m['points'][i].tolist()} outside the model: {mm.reasons[i]}"
            )
