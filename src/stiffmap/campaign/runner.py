"""``stiffmap run``: measure -> identify -> fit -> export (-> report) for a campaign directory.

The unit of work is a robot position: its images are measured in order (the
platform target is tracked from image to image) by a worker process, and the
parent writes all of the position's rows in one transaction. A position whose
images and parameters are unchanged since the last run is not measured again;
its displacements and stiffness are recomputed only when the load cases or the
identification settings changed. A run killed at any moment loses at most the
positions in flight, and the next run finishes them.

The camera does not move during a campaign, so ``cam2base`` is estimated once
per position from the fixed target in all of that position's images (mean
pose). Using each image's own fixed-target pose would add the fixed target's
noise, magnified by the lever arm between the two targets, to every displacement.
"""

from __future__ import annotations

import os
import time
import traceback
import warnings
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..camera import CameraModel, load_camera
from ..errors import InputError, StiffmapWarning
from ..geometry import displacement_from_poses, invert_transform, mean_transform
from ..identify import identify_stiffness
from ..loads import LoadCase, force_covariances, forces_matrix
from ..stats import describe, precision
from ..targets import Chessboard
from .spec import CampaignSpec, load_spec
from .store import DB_NAME, Store, from_json, model_fit_columns, params_hash, to_json

__all__ = ["PositionTask", "RunSummary", "plan", "run_campaign", "measure_position"]

#: Revisions of the code whose results the database keeps (with the stiffmap version in
#: every hash): bump one when a change alters what it computes, so that a re-run
#: recomputes it. MEASUREMENT: image -> board poses; DERIVATION: poses -> K.
MEASUREMENT_REVISION = 2
DERIVATION_REVISION = 2

# ------------------------------------------------------------------------ plan


@dataclass(frozen=True)
class Pair:
    """One measurement of one load case: an unloaded and a loaded image (relative paths)."""

    load: int
    repeat: int
    unloaded: str
    loaded: str


@dataclass(frozen=True)
class PositionTask:
    """The images of one robot position, in acquisition order (1-based indices)."""

    index: int
    xyz: tuple[float, float, float]
    images: tuple[str, ...]
    pairs: tuple[Pair, ...]
    missing: tuple[str, ...] = ()


def plan(spec: CampaignSpec, root: Path) -> list[PositionTask]:
    """The positions of a vision campaign with their image files (missing ones listed)."""
    positions = spec.positions.resolve()
    n_loads = len(spec.loads.resolve(spec.g))
    tasks = []
    for p, xyz in enumerate(positions, start=1):
        pairs, images, missing = [], [], []
        for ld in range(1, n_loads + 1):
            for r in range(1, spec.repeats + 1):
                u = spec.images.path("unloaded", p, ld, r)
                lo = spec.images.path("loaded", p, ld, r)
                pairs.append(Pair(ld, r, u, lo))
                for rel in (u, lo):
                    if rel not in images:
                        images.append(rel)
                        if not (root / rel).is_file():
                            missing.append(rel)
        tasks.append(
            PositionTask(
                p, (float(xyz[0]), float(xyz[1]), float(xyz[2])), tuple(images), tuple(pairs), tuple(missing)
            )
        )
    return tasks


# ------------------------------------------------------------------ measuring


@dataclass(frozen=True)
class MeasureContext:
    """What a worker needs to measure images (picklable)."""

    root: str
    camera: dict
    mobile: tuple[int, int, float]
    fixed: tuple[int, int, float] | None
    fixed2base: list | None
    refine: str = "auto"


@dataclass
class ImageRow:
    image: str
    ok: bool
    error: str | None = None
    mobile2cam: np.ndarray | None = None
    mobile_cov: np.ndarray | None = None
    fixed2cam: np.ndarray | None = None
    fixed_cov: np.ndarray | None = None
    rms_px: float | None = None
    n_corners: int | None = None
    tracked: bool = False
    seconds: float = 0.0


def measure_position(ctx: MeasureContext, task: PositionTask) -> list[ImageRow]:
    """Measure every existing image of a position (worker process). Never raises for an image."""
    from ..vision.sequence import measure_sequence

    camera = CameraModel.from_dict(ctx.camera)
    mobile = Chessboard(*ctx.mobile)
    fixed = Chessboard(*ctx.fixed) if ctx.fixed is not None else None
    root = Path(ctx.root)
    present = [rel for rel in task.images if rel not in task.missing]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffmapWarning)
        ms = measure_sequence(
            [root / rel for rel in present],
            camera,
            mobile,
            fixed,
            None,
            names=present,
            refine=ctx.refine,
            # The fixed target only orients the displacements, through its mean pose over the
            # position's images: corner poses are precise enough there.
            refine_fixed="corners",
        )
    rows = []
    for rel, m in zip(present, ms, strict=True):
        if m.error is not None or m.mobile is None:
            rows.append(
                ImageRow(
                    rel, False, m.error or "mobile target not measured", seconds=m.timings.get("total", 0)
                )
            )
            continue
        rms = [p.rms_px for p in (m.mobile, m.fixed) if p is not None]
        n = sum(p.n_corners for p in (m.mobile, m.fixed) if p is not None)
        row = ImageRow(
            rel,
            True,
            mobile2cam=m.mobile.board2cam,
            mobile_cov=m.mobile.cov,
            fixed2cam=None if m.fixed is None else m.fixed.board2cam,
            fixed_cov=None if m.fixed is None else m.fixed.cov,
            rms_px=float(np.sqrt(np.mean(np.square(rms)))),
            n_corners=int(n),
            tracked=bool(m.tracked),
            seconds=float(m.timings.get("total", 0.0)),
        )
        if fixed is not None and m.fixed is None:
            row.ok = False
            row.error = "fixed target not found"
        rows.append(row)
    return rows


def _measure_worker(ctx: MeasureContext, task: PositionTask) -> tuple[int, list[ImageRow] | str]:
    try:
        return task.index, measure_position(ctx, task)
    except Exception:  # a bug, not a user error: keep the message, let the run go on
        return task.index, "internal error while measuring:\n" + traceback.format_exc()


# ----------------------------------------------------------------- derivation


@dataclass
class PositionResult:
    """Derived rows of one position, ready to be written."""

    displacements: list[dict] = field(default_factory=list)
    repeat_stats: list[dict] = field(default_factory=list)
    stiffness: dict = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


def derive_position(
    task: PositionTask,
    rows: dict[str, ImageRow],
    loads: list[LoadCase],
    spec: CampaignSpec,
    method: str,
    inputs_hash: str,
    phash: str,
) -> PositionResult:
    """Displacements (base frame), repeat statistics and K of one position."""
    res = PositionResult()
    targets = spec.targets
    point = np.asarray(targets.mobile.point_mm, dtype=float)
    frame = "cam"
    cam2base = np.eye(4)
    fixed_ok = [r for r in rows.values() if r.ok and r.fixed2cam is not None]
    if targets.fixed is not None:
        if not fixed_ok:
            res.problems.append(f"position {task.index}: the fixed target was not found in any image")
        else:
            fixed2base = np.asarray(targets.fixed.fixed2base, dtype=float)
            cam2base = fixed2base @ invert_transform(mean_transform([r.fixed2cam for r in fixed_ok]))
            frame = "base"
    R = cam2base[:3, :3]
    B = np.zeros((6, 6))
    B[:3, :3] = R
    B[3:, 3:] = R
    mean_ref = spec.images.pairing == "mean-reference"
    if mean_ref:
        refs = [
            rows[rel]
            for rel in dict.fromkeys(pr.unloaded for pr in task.pairs)
            if rel in rows and rows[rel].ok
        ]
        if not refs:
            res.problems.append(f"position {task.index}: no usable unloaded image")
        else:
            ref_pose = mean_transform([r.mobile2cam for r in refs])
            ref_cov = sum(r.mobile_cov for r in refs) / len(refs) ** 2
    F_cols, D_cols = [], []
    per_load: dict[int, list[np.ndarray]] = {}
    for pr in task.pairs:
        u, lo = rows.get(pr.unloaded), rows.get(pr.loaded)
        row = {
            "position": task.index,
            "load": pr.load,
            "repeat": pr.repeat,
            "unloaded": "(mean of the position's unloaded images)" if mean_ref else pr.unloaded,
            "loaded": pr.loaded,
            "frame": frame,
            "params_hash": phash,
            "version": __version__,
        }
        bad = []
        for rel, r in ((pr.loaded, lo),) if mean_ref else ((pr.unloaded, u), (pr.loaded, lo)):
            if rel in task.missing:
                bad.append(f"missing image {rel}")
            elif r is None or not r.ok:
                bad.append(f"{rel}: {r.error if r is not None else 'not measured'}")
        if mean_ref and not refs:
            bad.append("no usable unloaded image")
        if bad or (targets.fixed is not None and not fixed_ok):
            # Without the fixed target the displacement cannot be put in the base frame.
            row.update(status="failed", error="; ".join(bad) or "the fixed target was not found in any image")
            res.displacements.append(row)
            continue
        M0, cov0 = (ref_pose, ref_cov) if mean_ref else (u.mobile2cam, u.mobile_cov)
        d = displacement_from_poses(cam2base @ M0, cam2base @ lo.mobile2cam, point)
        # (t, left r) pose noise moves the point R p + t by dt + dr x (R p).
        v = M0[:3, :3] @ point
        J = np.eye(6)
        J[:3, 3:] = -np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
        cov = B @ J @ (cov0 + lo.mobile_cov) @ J.T @ B.T
        row.update(status="ok", error=None, d=to_json(d), cov=to_json(cov))
        res.displacements.append(row)
        F_cols.append(loads[pr.load - 1].force)
        D_cols.append(d[:3])
        per_load.setdefault(pr.load, []).append(d)
    # Repeat statistics per load case: components and norm of the translation.
    for ld, ds in sorted(per_load.items()):
        arr = np.asarray(ds)
        quantities = {
            "dx": arr[:, 0],
            "dy": arr[:, 1],
            "dz": arr[:, 2],
            "norm": np.linalg.norm(arr[:, :3], axis=1),
        }
        quantities.update({"rx": arr[:, 3], "ry": arr[:, 4], "rz": arr[:, 5]})
        for q, vals in quantities.items():
            c = describe(vals)
            res.repeat_stats.append(
                {"position": task.index, "load": ld, "quantity": q, "mean": c.mean, "std": c.std, "n": c.n}
            )
    x, y, z = task.xyz
    st = {
        "position": task.index,
        "x": x,
        "y": y,
        "z": z,
        "method": method,
        "inputs_hash": inputs_hash,
        "params_hash": phash,
        "version": __version__,
        "n_obs": len(F_cols),
    }
    if len(F_cols) < 3:
        st.update(
            status="failed", error=f"only {len(F_cols)} usable load measurement(s); at least 3 are needed"
        )
        res.stiffness = st
        res.problems.append(f"position {task.index}: {st['error']}")
        return res
    F = np.asarray(F_cols).T
    D = np.asarray(D_cols).T
    try:
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always", StiffmapWarning)
            # Against a mean reference every displacement shares its error: estimate that offset.
            fit = identify_stiffness(F, D, method=method, offset=mean_ref)
    except (InputError, ValueError) as e:
        st.update(status="failed", error=str(e))
        res.stiffness = st
        res.problems.append(f"position {task.index}: {e}")
        return res
    idx = fit.indices
    prec = _precision(per_load)
    st.update(
        status="ok",
        error=None,
        K=to_json(fit.K),
        K_std=to_json(fit.K_std),
        K_cov=to_json(fit.K_cov),
        det=idx.det,
        eigenvalues=to_json(idx.eigenvalues),
        min_principal=idx.min_principal,
        K_condition=idx.condition,
        design_condition=fit.condition,
        rank=fit.rank,
        dof=fit.dof,
        residual_rms=to_json(fit.residual_rms),
        flags=to_json(list(fit.flags) + prec.pop("flags")),
        precision=to_json(prec),
    )
    res.stiffness = st
    return res


def _precision(per_load: dict[int, list[np.ndarray]]) -> dict[str, Any]:
    """Repeatability of the displacement components over the load cases (ISO 5725-2).

    The load cases are the conditions and the repeats the replicates; each
    component's deviations from its load case's mean are analysed, so s_r is
    the pooled repeatability. A flag is raised only when Cochran's C finds the
    largest within-load-case variance an outlier (1 %): that test already
    accounts for the number of load cases, whereas Mandel's k, tested load case
    by load case, would raise a false alarm at about one position in four (27
    tests at 1 % per position); its values are kept as information.
    """
    groups = {k: np.asarray(v) for k, v in per_load.items() if len(v) >= 2}
    out: dict[str, Any] = {"flags": []}
    if len(groups) < 2:
        return out
    labels = [f"load {k}" for k in groups]
    for j, name in enumerate(("dx", "dy", "dz")):
        res = precision([g[:, j] - g[:, j].mean() for g in groups.values()], labels)
        out[name] = {"s_r": res.s_r, "r": res.r, "mandel_k": res.k.tolist(), "cochran_C": res.cochran_C}
        out["flags"].extend(f"{name} repeatability outlier ({o})" for o in res.outliers if "Cochran" in o)
    return out


# ---------------------------------------------------------------------- model


def fit_and_evaluate_model(store: Store, spec: CampaignSpec) -> list[str]:
    """Evaluate the campaign's model at every position, fit it to the measured K, store both."""
    from ..models.fit import fit_stiffness

    problems: list[str] = []
    name = spec.robot.model
    if name == "none" or spec.kind != "vision":
        return problems
    if name != "delta":
        problems.append(f"robot model {name!r} has no 3D stiffness for a vision campaign; model step skipped")
        return problems
    try:
        model = spec.robot.mechanism()
    except ValueError as e:
        problems.append(f"campaign.toml robot.params: {e}")
        return problems
    rows = store.stiffness_rows()
    if not rows:
        return problems
    pts = np.array([[r["x"], r["y"], r["z"]] for r in rows], dtype=float)
    ok = [r for r in rows if r["status"] == "ok"]
    ihash = params_hash(
        {"model": name, "params": spec.robot.params, "xyz": pts.tolist(), "K": [r["K"] for r in ok]}
    )
    fitted = model
    fit_row: dict[str, Any] = {
        "name": "stiffness",
        "model": name,
        "inputs_hash": ihash,
        "version": __version__,
    }
    fit_names = spec.robot.fitted_names()
    if len(ok) >= 1:
        try:
            mm = model.evaluate(np.array([[r["x"], r["y"], r["z"]] for r in ok]))
            good = [r for r, v in zip(ok, mm.valid, strict=True) if v]
            if not good:
                raise InputError("no measured position lies inside the model's workspace")
            fit = fit_stiffness(
                model,
                np.array([[r["x"], r["y"], r["z"]] for r in good]),
                np.array([from_json(r["K"]) for r in good]),
                params=fit_names,
                K_std=np.array([from_json(r["K_std"]) for r in good]),
            )
            fitted = fit.model
            fit_row.update(model_fit_columns(fit, fit.residual_rms_per_pose))
        except (InputError, ValueError) as e:
            fit_row.update(status="failed", error=str(e))
            problems.append(f"model fit: {e}")
    else:
        fit_row.update(status="failed", error="no measured stiffness to fit")
    mm = fitted.evaluate(pts)
    per_position = []
    for r, K, valid, reason, det, lam in zip(
        rows, mm.K, mm.valid, mm.reasons, mm.det, mm.min_principal, strict=True
    ):
        per_position.append(
            {
                "position": r["position"],
                "model": name,
                "valid": int(bool(valid)),
                "reason": reason or None,
                "K": to_json(K) if valid else None,
                "det": float(det) if valid else None,
                "min_principal": float(lam) if valid else None,
                "inputs_hash": ihash,
            }
        )
        if not valid:
            where = f"({r['x']:g}, {r['y']:g}, {r['z']:g})"
            problems.append(f"position {r['position']} {where}: outside the model: {reason}")
    store.save_model_stiffness(fit_row, per_position)
    return problems


# ------------------------------------------------------------------------ run


@dataclass
class RunSummary:
    """What ``run_campaign`` did."""

    campaign: str
    positions: int = 0
    measured: int = 0
    reused: int = 0
    rederived: int = 0  # images unchanged, results computed again (other parameters)
    images: int = 0
    image_seconds: float = 0.0
    wall_seconds: float = 0.0
    failures: list[str] = field(default_factory=list)
    db: str = ""


#: ``progress(images_done, images_total, images_measured)`` after each position.
ProgressHook = Callable[[int, int, int], None]


def _ctx(spec: CampaignSpec, root: Path, camera: CameraModel) -> MeasureContext:
    t = spec.targets
    mob = Chessboard.parse(t.mobile.board, t.mobile.square_mm)
    fix = Chessboard.parse(t.fixed.board, t.fixed.square_mm) if t.fixed is not None else None
    return MeasureContext(
        root=str(root),
        camera=camera.to_dict(),
        mobile=(mob.cols, mob.rows, mob.square_mm),
        fixed=None if fix is None else (fix.cols, fix.rows, fix.square_mm),
        fixed2base=t.fixed.fixed2base if t.fixed is not None else None,
        refine=spec.measurement.refine,
    )


def _image_row_from_db(r) -> ImageRow:
    return ImageRow(
        image=r["image"],
        ok=r["status"] == "ok",
        error=r["error"],
        mobile2cam=from_json(r["mobile2cam"]),
        mobile_cov=from_json(r["mobile_cov"]),
        fixed2cam=from_json(r["fixed2cam"]),
        fixed_cov=from_json(r["fixed_cov"]),
        rms_px=r["rms_px"],
        n_corners=r["n_corners"],
        tracked=bool(r["tracked"]),
        seconds=r["seconds"] or 0.0,
    )


def run_campaign(
    campaign_dir: str | Path,
    *,
    workers: int = 1,
    method: str = "compliance",
    progress: ProgressHook | None = None,
) -> RunSummary:
    """Run a vision campaign: measure every position, identify K, fit the model.

    Parameters
    ----------
    campaign_dir : path
        Directory holding ``campaign.toml``.
    workers : int
        Processes measuring positions in parallel (1: in this process).
    method : str
        Identification method (see :func:`stiffmap.identify.identify_stiffness`).
    progress : callable, optional
        ``progress(images_done, images_total, images_measured)`` after each
        position (reused positions count as done but not as measured).

    Returns
    -------
    RunSummary
        ``failures`` lists every image, position or step that failed (the run
        goes on past them).

    Raises
    ------
    InputError
        When nothing can be done: no or bad campaign.toml, camera file missing or
        malformed.
    """
    t_start = time.perf_counter()
    root = Path(campaign_dir).resolve()
    spec = load_spec(root)
    if spec.kind != "vision":
        raise InputError(
            f"{root / 'campaign.toml'}: kind = {spec.kind!r}: use 'stiffmap run' on vision campaigns"
        )
    camera_path = root / spec.camera.file
    camera = load_camera(camera_path)
    try:
        loads = spec.loads.resolve(spec.g)
        tasks = plan(spec, root)
    except ValueError as e:
        raise InputError(str(e), source=str(root / "campaign.toml")) from None
    summary = RunSummary(campaign=spec.name, positions=len(tasks), db=str(root / DB_NAME))
    if tasks and all(len(t.missing) == len(t.images) for t in tasks):
        raise InputError(
            f"no image found: none of the {sum(len(t.images) for t in tasks)} files that [images] "
            f"names exists (e.g. {tasks[0].images[0]!r}, from unloaded = {spec.images.unloaded!r}); "
            "check the patterns and the image folder",
            source=str(root / "campaign.toml"),
        )
    for t in tasks:
        for rel in t.missing:
            summary.failures.append(f"{rel}: image not found (position {t.index})")
    ctx = _ctx(spec, root, camera)
    with Store(root / DB_NAME) as store:
        run_id = store.begin_run({"workers": workers, "method": method})
        mphash = params_hash(
            {
                "camera": store.sha256(camera_path),
                "mobile": ctx.mobile,
                "fixed": ctx.fixed,
                "refine": ctx.refine,
                "what": "measure",
                "revision": MEASUREMENT_REVISION,
            }
        )
        dphash = params_hash(
            {
                "measure": mphash,
                "method": method,
                "point": list(spec.targets.mobile.point_mm),
                "pairing": spec.images.pairing,
                "revision": DERIVATION_REVISION,
                "fixed2base": ctx.fixed2base,
                "forces": forces_matrix(loads),
                "force_cov": force_covariances(loads),
            }
        )
        # Decide per position: reuse, re-derive, or measure.
        to_measure: list[PositionTask] = []
        cached: dict[int, dict[str, ImageRow]] = {}
        hashes: dict[int, str] = {}
        with store.transaction():
            # Positions no longer in campaign.toml leave the results (indices run 1..n).
            store.delete_positions_after(len(tasks))
            for t in tasks:
                shas = {rel: store.sha256(root / rel) for rel in t.images if rel not in t.missing}
                hashes[t.index] = params_hash(
                    {"derive": dphash, "xyz": list(t.xyz), "images": shas, "missing": t.missing}
                )
                prev = {r["image"]: r for r in store.measurement_rows(t.index)}
                complete = all(
                    rel in prev and prev[rel]["sha256"] == sha and prev[rel]["params_hash"] == mphash
                    for rel, sha in shas.items()
                )
                if complete:
                    cached[t.index] = {rel: _image_row_from_db(prev[rel]) for rel in shas}
                else:
                    to_measure.append(t)
        by_index = {t.index: t for t in tasks}
        done = 0
        measured_images = 0
        total = sum(len(t.images) for t in tasks)

        def finish(t: PositionTask, rows: list[ImageRow] | None) -> None:
            nonlocal done, measured_images
            rowmap = {r.image: r for r in rows} if rows is not None else cached[t.index]
            if rows is None and store.stiffness_inputs_hash(t.index) == hashes[t.index]:
                summary.reused += 1
            else:
                if rows is None:
                    summary.rederived += 1
                derived = derive_position(t, rowmap, loads, spec, method, hashes[t.index], dphash)
                with store.transaction():
                    measurements = None
                    if rows is not None:
                        measurements = [
                            {
                                "image": r.image,
                                "position": t.index,
                                "board_set": f"{ctx.mobile}|{ctx.fixed}",
                                "sha256": store.sha256(root / r.image),
                                "params_hash": mphash,
                                "version": __version__,
                                "status": "ok" if r.ok else "failed",
                                "error": r.error,
                                "mobile2cam": to_json(r.mobile2cam),
                                "mobile_cov": to_json(r.mobile_cov),
                                "fixed2cam": to_json(r.fixed2cam),
                                "fixed_cov": to_json(r.fixed_cov),
                                "mobile2base": None,
                                "base_cov": None,
                                "rms_px": r.rms_px,
                                "n_corners": r.n_corners,
                                "tracked": int(r.tracked),
                                "seconds": r.seconds,
                            }
                            for r in rows
                        ]
                    store.save_position(
                        t.index,
                        measurements=measurements,
                        displacements=derived.displacements,
                        repeat_stats=derived.repeat_stats,
                        stiffness=derived.stiffness,
                    )
                summary.failures.extend(derived.problems)
            if rows is not None:
                summary.measured += 1
                summary.images += len(rows)
                summary.image_seconds += sum(r.seconds for r in rows)
                summary.failures.extend(f"{r.image}: {r.error}" for r in rows if not r.ok)
                measured_images += len(t.images)
            done += len(t.images)
            if progress is not None:
                progress(done, total, measured_images)

        for t in tasks:
            if t.index in cached:
                finish(t, None)
        if to_measure:
            if workers <= 1:
                for t in to_measure:
                    finish(t, measure_position(ctx, t))
            else:
                with ProcessPoolExecutor(max_workers=workers) as pool:
                    pending = {pool.submit(_measure_worker, ctx, t) for t in to_measure}
                    while pending:
                        finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                        for fut in finished:
                            idx, rows = fut.result()
                            if isinstance(rows, str):
                                summary.failures.append(f"position {idx}: {rows.splitlines()[-1]}")
                                done += len(by_index[idx].images)
                                continue
                            finish(by_index[idx], rows)
        summary.failures.extend(fit_and_evaluate_model(store, spec))
        summary.wall_seconds = time.perf_counter() - t_start
        store.end_run(run_id, "done", {"failures": len(summary.failures)})
    return summary


def default_workers() -> int:
    """Worker processes by default: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover
        return max(1, os.cpu_count() or 1)
