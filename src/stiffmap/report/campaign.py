"""A campaign's report: its database mapped onto the report's data contract.

The report sits above the campaign layer (DESIGN.md): it reads the campaign's
spec and ``stiffmap.db`` and fills :class:`stiffmap.report.data.ReportData`;
:func:`write_campaign_report` writes ``CAMPAIGN/report/``.
"""

from __future__ import annotations

import base64
import warnings
from datetime import date
from pathlib import Path

import numpy as np

from ..campaign.fingerprint import robot_changes, stale_fit_message
from ..campaign.instruments import STATIC_ERROR, STIFFNESS, instrument_of
from ..campaign.paths import ALLOW_OUTSIDE_OPTION, own_file
from ..campaign.platform import is_platform, platform_map
from ..campaign.robot import campaign_model, robot_file
from ..campaign.run import EXPORTS_DIR
from ..campaign.runner import cameras_path, read_cameras
from ..campaign.sensor_runner import measured_static_errors
from ..campaign.spec import CampaignSpec, load_spec
from ..campaign.store import DB_NAME, Store
from ..campaign.truth import TRUTH_NAME, load_truth
from ..errors import InputError, StiffmapWarning
from ..rig import Rig
from ..targets import Chessboard
from ..textfmt import fmt
from ..vision.images import read_image
from . import data as contract
from . import write_report
from .figure_data import displacement_residuals
from .orientations import map_poses, orientation_map
from .png import grey_png, reduce_image

__all__ = ["report_data", "failures_as_items", "write_campaign_report"]


def failures_as_items(failures: list[str]):
    """``Failure(item, message)`` records from "item: message" strings."""
    out = []
    for f in failures:
        item, _, msg = f.partition(": ")
        out.append(contract.Failure(item or "run", msg or f))
    return tuple(out)


def _parameters(store: Store, name: str, spec: CampaignSpec):
    fit = store.model_fit(name)
    if fit is None or fit.status != "ok":
        return ()
    est = fit.params
    std = fit.std
    kind = spec.robot.kind
    return tuple(
        contract.Parameter(
            k, float(v), float(std.get(k, np.nan)) if std else np.nan, kind.param_unit(k) if kind else ""
        )
        for k, v in est.items()
    )


def _fitted_model(root: Path, spec: CampaignSpec, store: Store, fit_name: str):
    return campaign_model(spec, root, **{p.name: p.value for p in _parameters(store, fit_name, spec)})


def _stale_model(root: Path, spec: CampaignSpec, store: Store, fit_name: str) -> str | None:
    """Why the report leaves the model out (None: it does not): campaign.toml's robot changed
    since the run, so that the stored fit is another robot's, or no longer builds it."""
    fit = store.model_fit(fit_name)
    if fit is None:
        return None
    rerun = f"run 'stiffmap run {root}' again to fit it; the report leaves the model out"
    if fit.model != spec.robot.model:
        return (
            f"model fit: {DB_NAME} holds the fit of robot model {fit.model!r}, but campaign.toml now "
            f"names {spec.robot.model!r}: {rerun}"
        )
    changes = robot_changes(fit.robot, spec, root, fit.params or ())
    if changes:
        return f"model fit: {stale_fit_message(changes, root)}; the report leaves the model out"
    try:
        _fitted_model(root, spec, store, fit_name)
    except (ValueError, TypeError, KeyError) as e:  # InputError too
        return f"model fit: the fit in {DB_NAME} no longer builds campaign.toml's robot ({e}): {rerun}"
    return None


def _model_stiffness(model, spec: CampaignSpec, store: Store, Km, g, rows, measured):
    """The model's K at the positions, its dense map at ``g`` and, for a platform that turns,
    its map over orientations (:mod:`.orientations`: the platform at the campaign's shared
    orientation or level, the loads hung at ``loads.point_mm``)."""
    turns = None
    if is_platform(model):
        lever = spec.loads.point_mm or (0.0, 0.0, 0.0)
        mm = platform_map(model, map_poses(spec, g), lever)
        numbers = [r.position for r in rows]
        mp = np.where(measured.ok, measured.min_principal, np.nan)
        turns = orientation_map(model, spec, [[r.x, r.y, r.z] for r in rows], numbers, mp)
    else:
        mm = model.evaluate(g)
    dense = contract.ModelMap(
        g, np.where(mm.valid, mm.det, np.nan), np.where(mm.valid, mm.min_principal, np.nan)
    )
    params = _parameters(store, "stiffness", spec)
    return contract.ModelStiffness.from_K(
        spec.robot.model, params, Km, map=dense, orientations=turns, notes=_fit_notes(store, "stiffness")
    )


def _fit_notes(store: Store, name: str) -> tuple[str, ...]:
    """What the stored fit accounted for (``model_fit.info``; none before schema 5)."""
    fit = store.model_fit(name)
    info = fit.info if fit is not None and fit.status == "ok" else None
    return tuple(str(n) for n in info) if isinstance(info, list) else ()


def _vision(root: Path, spec: CampaignSpec, store: Store, allow_outside: bool = False) -> dict:
    rows = store.stiffness_rows()
    n = len(rows)
    if not any(r.status == "ok" for r in rows):
        return {}
    pos = np.array([[r.x, r.y, r.z] for r in rows], dtype=float)
    K = np.full((n, 3, 3), np.nan)
    S = np.full((n, 3, 3), np.nan)
    share = np.full((n, 3), np.nan)
    for i, r in enumerate(rows):
        if r.status == "ok":
            K[i] = r.K
            S[i] = r.K_std
            cal, cov = r.K_cov_calibration, r.K_cov
            if cal is not None and cov is not None:
                with np.errstate(invalid="ignore", divide="ignore"):
                    share[i] = np.clip(np.diag(cal)[[0, 4, 8]] / np.diag(cov)[[0, 4, 8]], 0.0, 1.0)
    measured = contract.MeasuredStiffness.from_K(
        pos,
        K,
        S,
        status=[r.status for r in rows],
        messages=[r.error or "" for r in rows],
        flags=[tuple(r.flags or ()) for r in rows],
    )
    out: dict = {"measured": measured}
    loads = spec.loads.resolve(spec.g)
    forces = np.stack([ld.force for ld in loads])
    vectors = np.full((n, len(loads), spec.repeats, 3), np.nan)
    index = {r.position: i for i, r in enumerate(rows)}
    for d in store.displacement_rows(only_ok=True):
        i = index.get(d.position)
        if i is not None and d.load <= len(loads) and d.repeat <= spec.repeats:
            vectors[i, d.load - 1, d.repeat - 1] = d.d[:3]
    offset = spec.images.pairing == "mean-reference"
    out["loads"] = contract.LoadData(
        tuple(ld.label for ld in loads),
        forces,
        np.linalg.norm(vectors, axis=3),
        vectors=vectors,
        residuals=displacement_residuals(K, forces, vectors, offset=offset),
    )
    kind = spec.robot.kind
    stale = _stale_model(root, spec, store, "stiffness") if kind is not None else None
    if kind is not None and kind.dim != 2 and stale is None:  # a spatial model (a legs TOML: its dim)
        model = _fitted_model(root, spec, store, "stiffness")
        Km = np.full((n, 3, 3), np.nan)
        for r in store.model_stiffness_rows():
            i = index.get(r.position)
            if i is not None and r.valid:
                Km[i] = r.K
        # A dense map on the measured planes, over the measured x-y extent.
        grid = []
        for z in np.unique(pos[:, 2]):
            xs = np.linspace(pos[:, 0].min(), pos[:, 0].max(), 25)
            ys = np.linspace(pos[:, 1].min(), pos[:, 1].max(), 25)
            X, Y = np.meshgrid(xs, ys)
            grid.append(np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)])
        g = np.concatenate(grid)
        out["model"] = _model_stiffness(model, spec, store, Km, g, rows, measured)
    truth = _truth_K(root, n, allow_outside)
    if truth is not None:
        out["truth"] = contract.TruthStiffness(truth)
    cameras_path(spec, root, allow_outside=allow_outside)  # a file outside the directory: refused
    try:
        _, rig = read_cameras(spec, root, allow_outside=allow_outside)
        cameras = _per_camera(rig, store) if spec.cameras is not None else ()
        out["calibration"] = contract.CalibrationData(
            rig.cameras[0].camera.to_dict(), k_share=share, cameras=cameras
        )
    except (InputError, ValueError):
        return out  # the report goes without the calibration section and the board image
    out["board_image"] = board_image(root, spec, store, rig)
    return out


def board_image(root: Path, spec: CampaignSpec, store: Store, rig: Rig) -> contract.BoardImage | None:
    """The first measured image with its boards where their measured poses put them.

    The boards' inner corners are projected from the stored poses (``mobile2cam``,
    ``fixed2cam``: camera frame, or the rig frame, which is the first camera's) through the
    (first) camera. None when no image was measured or the file cannot be read any more.
    """
    mi = store.first_measured_image()
    if mi is None or spec.targets is None:
        return None
    cam = rig.cameras[0]
    name = mi.image.replace("{camera}", cam.name)
    try:
        image = read_image(root / name)
    except InputError:
        return None
    corners, which = [], []
    for label, target, T in (
        ("mobile", spec.targets.mobile, mi.mobile2cam),
        ("fixed", spec.targets.fixed, mi.fixed2cam),
    ):
        if target is None or T is None or not np.all(np.isfinite(T)):
            continue
        board = Chessboard.parse(target.board, target.square_mm)
        P = board.object_points() @ T[:3, :3].T + T[:3, 3]
        px = cam.camera.project(P)
        corners.append(px)
        which += [f"{label} {board.size}"] * len(px)
    if not corners:
        return None
    small, k = reduce_image(image)
    h, w = image.shape
    return contract.BoardImage(
        name=name,
        png_base64=base64.b64encode(grey_png(small)).decode("ascii"),
        image_size=np.array([w, h], dtype=float),
        scale=float(k),
        corners_px=np.concatenate(corners),
        corner_board=tuple(which),
    )


def _per_camera(rig: Rig, store: Store) -> tuple[dict, ...]:
    """What each camera of a rig gave over the campaign's image sets (``measurements.per_camera``)."""
    seen: dict[str, list[float]] = {n: [] for n in rig.names}
    found = dict.fromkeys(rig.names, 0)
    errors: dict[str, list[str]] = {n: [] for n in rig.names}
    n_sets = 0
    for r in store.measurement_rows():
        per = r.per_camera
        if not isinstance(per, list):
            continue
        n_sets += 1
        for c in per:
            name = c.get("name") if isinstance(c, dict) else None
            if name not in seen:
                continue
            if c.get("boards"):
                found[name] += 1
                if isinstance(c.get("rms_px"), (int, float)):
                    seen[name].append(float(c["rms_px"]))
            if c.get("error") and len(errors[name]) < 3:
                errors[name].append(str(c["error"]))
    out = []
    for rc in rig.cameras:
        v = np.asarray(seen[rc.name])
        out.append(
            {
                "name": rc.name,
                "camera": rc.camera.to_dict(),
                "cam2rig": rc.cam2rig.tolist(),
                "sets": n_sets,
                "seen": found[rc.name],
                "rms_px": float(np.median(v)) if v.size else None,
                "rms_px_p95": float(np.percentile(v, 95)) if v.size else None,
                "errors": errors[rc.name],
            }
        )
    return tuple(out)


def _truth_K(root: Path, n: int, allow_outside: bool = False) -> np.ndarray | None:
    """The true K of the ``n`` positions from a simulated campaign's ``truth.json``, if it has them.

    ``truth.json`` is an optional extra of simulated campaigns: one that cannot be read, or
    that holds something else than ``n`` finite 3x3 matrices, is left out of the report; one
    that leads outside the campaign (a symbolic link) too, with a warning, unless
    ``allow_outside``.
    """
    out = own_file(root, TRUTH_NAME, allow_outside=allow_outside)
    if out is not None:
        warnings.warn(
            f"{out}: left out of the report (give {ALLOW_OUTSIDE_OPTION} to read it)",
            StiffmapWarning,
            stacklevel=2,
        )
        return None
    try:
        t = load_truth(root)
        Kt = np.asarray(t.K, dtype=float)
    except (InputError, OSError, ValueError, KeyError, TypeError, RecursionError):
        return None
    if Kt.shape != (n, 3, 3) or not np.all(np.isfinite(Kt)):
        return None
    return Kt


def _sensor(root: Path, spec: CampaignSpec, store: Store, allow_outside: bool = False) -> dict:
    m = measured_static_errors(spec, store)
    if m["points"].shape[1] != 2:
        return {}
    pred = store.model_static_errors()
    model_um = None
    maps: tuple = ()
    middle = None
    name = ""
    params: tuple = ()
    kind = spec.robot.kind
    stale = _stale_model(root, spec, store, "static_error") if kind is not None else None
    if kind is not None and kind.report_grid is not None and stale is None:  # a planar kind's map
        name = kind.name
        params = _parameters(store, "static_error", spec)
        model_um = np.array([1e3 * pred[f] if pred.get(f) is not None else np.nan for f in m["files"]])
        model = _fitted_model(root, spec, store, "static_error")
        g, middle_x = kind.report_grid(model)
        mm = model.evaluate(g)
        ref = m["reference_load_n"]
        dirs = sorted({_axis(u) for u in m["directions"]})
        maps = tuple(
            contract.SensorMap(a, g, 1e3 * mm.static_error(ref * _unit(a))[:, "xy".index(a)])
            for a in dirs
            if a in ("x", "y")
        )
        middle = None if middle_x is None else np.abs(m["points"][:, 0] - middle_x) < 1e-6
        if middle is not None and not middle.any():
            middle = None
    steps = _sensor_steps(spec, store)
    sr = contract.SensorResults(
        points=m["points"],
        direction=tuple(_axis(u) for u in m["directions"]),
        error_um=1e3 * m["value_mm"],
        error_std_um=1e3 * m["std_mm"],
        labels=tuple(r.label or Path(r.file).stem for r in spec.sensor.recordings),
        model_error_um=model_um,
        middle_line=middle,
        reference_load_n=m["reference_load_n"],
        model_name=name,
        parameters=params,
        maps=maps,
        **steps,
    )
    return {"sensor": sr}


def _sensor_steps(spec: CampaignSpec, store: Store) -> dict:
    """Each recording's plateaus (load, displacement) and fitted line, in spec order (NaN-padded)."""
    recs = spec.sensor.recordings
    rows = {r.recording: r for r in store.sensor_result_rows()}
    results = []
    for r in recs:
        row = rows.get(r.file)
        res = row.result if row is not None and row.status == "ok" else None
        results.append(res if isinstance(res, dict) else None)
    S = max((len(res.get("steps") or []) for res in results if res is not None), default=0)
    if S == 0:
        return {}
    load = np.full((len(recs), S), np.nan)
    disp = np.full((len(recs), S), np.nan)
    slope = np.full(len(recs), np.nan)
    icpt = np.full(len(recs), np.nan)
    for i, res in enumerate(results):
        if res is None:
            continue
        for k, st in enumerate(res.get("steps") or []):
            load[i, k], disp[i, k] = _number(st.get("load_n")), _number(st.get("displacement_um"))
        slope[i] = _number(res.get("compliance_um_per_n"))
        icpt[i] = _number(res.get("intercept_um"))
    return {"step_load_n": load, "step_um": disp, "fit_um_per_n": slope, "fit_intercept_um": icpt}


def _number(v) -> float:
    """A stored number, NaN for a missing one (null)."""
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else np.nan


def _axis(u: np.ndarray) -> str:
    k = int(np.argmax(np.abs(u)))
    return "xyz"[k]


def _unit(axis: str) -> np.ndarray:
    u = np.zeros(2)
    u["xy".index(axis)] = 1.0
    return u


#: The report's sections of what an instrument measures.
_SECTIONS = {STIFFNESS: _vision, STATIC_ERROR: _sensor}
#: The model fit each kind of result is fitted by (the `model_fit` row).
_FIT_NAME = {STIFFNESS: "stiffness", STATIC_ERROR: "static_error"}


def report_data(
    root: Path, spec: CampaignSpec, store: Store, failures: list[str], *, allow_outside: bool = False
):
    """The :class:`~stiffmap.report.data.ReportData` of a campaign, from its database.

    Raises
    ------
    InputError
        The database holds no result of the campaign yet (no position, or no recording).
    """
    info = contract.CampaignInfo(
        name=spec.name, kind=spec.kind, date=date.today().isoformat(), campaign_dir=str(root)
    )
    inst = instrument_of(spec)
    rows = inst.rows(store)
    if not any(r.status == "ok" for r in rows):
        verb = "measured" if inst.item == "position" else "analysed"
        raise InputError(
            f"no {inst.item} has results in {DB_NAME} (none could be {verb}, {len(rows)} failed: see "
            f"{EXPORTS_DIR}/summary.json): nothing to report",
            source=str(root),
        )
    robot_file(spec, root, allow_outside=allow_outside)  # a robot file outside the directory: refused
    stale = _stale_model(root, spec, store, _FIT_NAME[inst.measures]) if spec.robot.kind else None
    if stale is not None:
        warnings.warn(stale, StiffmapWarning, stacklevel=2)
        failures = [*failures, stale]
    parts = _SECTIONS[inst.measures](root, spec, store, allow_outside)
    setup = _SETUP[inst.measures](spec, store, parts)
    setup.append(("failures", f"{len(failures)} (each listed under Failures)" if failures else "none"))
    return contract.ReportData(
        campaign=info,
        failures=failures_as_items(failures),
        setup=tuple(contract.SetupItem(a, b) for a, b in setup),
        **parts,
    )


def _vision_setup(spec: CampaignSpec, store: Store, parts: dict) -> list[tuple[str, str]]:
    """The set-up summary of a vision campaign: what was loaded, imaged, measured, identified."""
    m, ld = parts["measured"], parts["loads"]
    z = np.unique(np.round(m.positions[:, 2], 6))
    out = [
        ("robot", spec.robot.model),
        ("positions", f"{m.n} on {len(z)} plane(s) z = {', '.join(fmt(v, 5) for v in z[::-1])} mm"),
        (
            "load cases",
            f"{len(ld.labels)}, {spec.repeats} repeat(s) each: "
            + "; ".join(
                f"{j + 1}: {lab} ({', '.join(fmt(f, 4) for f in ld.forces[j])} N)"
                for j, lab in enumerate(ld.labels)
            ),
        ),
    ]
    c = store.image_counts()
    where = f"{c.positions} position" + ("s" if c.positions != 1 else "")
    out.append(("images", f"{c.measured} of {c.total} measured, {c.failed} failed ({where})"))
    disp = store.displacement_rows()
    n_ok = sum(1 for r in disp if r.status == "ok")
    out.append(("load measurements", f"{n_ok} of {len(disp)} displacements measured"))
    pairing = {
        "pairs": "each loaded image against its own unloaded image",
        "mean-reference": "against the mean of the position's unloaded images (the common offset estimated)",
    }
    out.append(("pairing", pairing[spec.images.pairing]))
    t = spec.targets
    if t is not None:
        text = f"mobile {t.mobile.board}, {fmt(t.mobile.square_mm, 5)} mm squares"
        if t.fixed is not None:
            text += f"; fixed {t.fixed.board}, {fmt(t.fixed.square_mm, 5)} mm squares"
        out.append(("targets", text))
    cal = parts.get("calibration")
    if cal is not None:
        cam = cal.camera
        views = cam.get("views") or []
        used = sum(1 for v in views if v.get("used", True))
        text = f"{cam['image_size'][0]}x{cam['image_size'][1]} px, {cam.get('model', 'opencv')} lens model"
        if views:
            text += f", calibrated from {used} of {len(views)} views"
        if cam.get("rms_px") is not None:
            text += f", RMS {fmt(cam['rms_px'], 3)} px"
        if cal.cameras:
            text = f"a rig of {len(cal.cameras)} cameras; the first: " + text
        out.append(("camera", text))
    methods = sorted({r.method for r in store.stiffness_rows() if r.method})
    flagged = sum(1 for i in range(m.n) if m.ok[i] and m.flags[i])
    out.append(
        (
            "stiffness",
            f"{int(m.ok.sum())} of {m.n} positions identified ({', '.join(methods) or 'n/a'}), "
            f"{flagged} flagged, {int((~m.ok).sum())} failed",
        )
    )
    return out


def _sensor_setup(spec: CampaignSpec, store: Store, parts: dict) -> list[tuple[str, str]]:
    """The set-up summary of a sensor campaign: recordings, loads, conversion, results."""
    sn = spec.sensor
    rows = store.sensor_result_rows()
    ok = sum(1 for r in rows if r.status == "ok")
    s = parts["sensor"]
    pts = {tuple(p) for p in np.round(s.points, 6)}
    if sn.steps_kgf is not None:
        steps = ", ".join(fmt(v, 4) for v in sn.steps_kgf) + " kgf"
    elif sn.steps_n is not None:
        steps = ", ".join(fmt(v, 4) for v in sn.steps_n) + " N"
    else:
        steps = f"read from the load channel ({sn.load_unit})"
    return [
        ("robot", spec.robot.model),
        ("recordings", f"{ok} of {len(sn.recordings)} analysed, {len(sn.recordings) - ok} failed"),
        ("points", f"{len(pts)}, loaded along {', '.join(s.directions)}"),
        ("load steps", steps),
        ("reference load", f"{fmt(sn.reference_load_n, 5)} N (the static error is given at it)"),
        ("displacement sensor", f"{fmt(sn.scale_um_per_v, 5)} µm/V, range ±{fmt(sn.range_v, 4)} V"),
    ]


_SETUP = {STIFFNESS: _vision_setup, STATIC_ERROR: _sensor_setup}


def write_campaign_report(
    campaign_dir: str | Path,
    failures: list[str] | None = None,
    out_dir: str | Path | None = None,
    *,
    png: bool = True,
    allow_outside: bool = False,
) -> Path:
    """Write ``CAMPAIGN/report/`` (index.html, PNGs, data.json) from the campaign's database.

    ``out_dir`` writes the report elsewhere; ``png=False`` leaves out the PNG figures;
    ``allow_outside`` lets ``camera.file`` (read for the calibration section) lead outside
    the campaign directory (:mod:`stiffmap.campaign.paths`; refused otherwise).

    Returns
    -------
    Path
        The report's ``index.html``.
    """
    root = Path(campaign_dir).resolve()
    spec = load_spec(root)
    out = own_file(root, DB_NAME, allow_outside=allow_outside)
    if out is not None:  # another folder's results
        raise InputError(f"{out}: remove the link (or give {ALLOW_OUTSIDE_OPTION})", source=str(root))
    if not (root / DB_NAME).is_file():
        raise InputError(
            f"no results yet ({DB_NAME} missing): run 'stiffmap run {campaign_dir}' first", source=str(root)
        )
    with Store(root / DB_NAME) as store:
        data = report_data(root, spec, store, list(failures or []), allow_outside=allow_outside)
    return write_report(data, Path(out_dir) if out_dir is not None else root / "report", png=png)
