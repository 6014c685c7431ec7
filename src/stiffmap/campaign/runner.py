"""``stiffmap run``: measure -> identify -> fit for a vision campaign directory.

:func:`run_vision_campaign` follows ``docs/campaigns.md`` ("What ``stiffmap run`` does"):

1. **plan** (:mod:`~stiffmap.campaign.positions`): the positions and their image
   files; then, against the database, which positions are unchanged since the
   last run, which only need deriving again and which must be measured;
2. **measure** (:mod:`~stiffmap.campaign.measure`): the board poses of every
   image, one robot position per task, in a pool of processes;
3. **derive** (:mod:`~stiffmap.campaign.derive`): displacements, repeat
   statistics and K of each position;
4. **persist**: all of a position's rows in one transaction
   (:meth:`~stiffmap.campaign.store.Store.save_position`);
5. **model**: the campaign's model fitted to the measured K and evaluated at
   every position.

A position whose images and parameters are unchanged since the last run is not
measured again; its displacements and stiffness are recomputed only when the
load cases or the identification settings changed. What is unchanged is told by
hashes: of each image (SHA-256), of the measurement parameters (with
:data:`MEASUREMENT_REVISION`) and of the derivation parameters (with
:data:`DERIVATION_REVISION`). A run killed at any moment loses at most the
positions in flight, and the next run finishes them.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..camera import load_camera
from ..errors import InputError
from ..loads import LoadCase, force_covariances, forces_matrix
from ..models.fit import fit_stiffness, separation_notes
from ..models.joint_fit import fit_joint_compliances
from ..parallel import Backend, connected
from ..rig import Rig, load_rig
from .derive import derive_position
from .fingerprint import robot_fingerprint
from .flags import campaign_flags
from .measure import ImageRow, MeasureContext, measure_positions, workers_see_images
from .paths import campaign_file
from .platform import fit_platform, is_platform, platform_map
from .positions import PositionTask, campaign_poses, plan
from .rig_checks import rig_failures
from .robot import campaign_model
from .robot import fitted_names as campaign_fitted_names
from .spec import SPEC_NAME, CampaignSpec, load_spec
from .store import DB_NAME, Store, model_fit_columns, params_hash, to_json

__all__ = ["RunSummary", "run_vision_campaign", "fit_and_evaluate_model"]

#: Revisions of the code whose results the database keeps (with the stiffmap version in
#: every hash): bump one when a change alters what it computes, so that a re-run
#: recomputes it. MEASUREMENT: image -> board poses; DERIVATION: poses -> K.
MEASUREMENT_REVISION = 8
DERIVATION_REVISION = 3


@dataclass
class RunSummary:
    """What ``run_vision_campaign`` did."""

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
    #: Where the images were measured ("2 process(es)", "the Dask cluster at ...; images ...").
    backend: str = ""
    #: What the user should know that is not a failure (a Dask worker that died, its tasks re-run).
    notes: list[str] = field(default_factory=list)
    #: What a fit accounted for and the reader should know (an extra noise estimated): no action.
    info: list[str] = field(default_factory=list)
    #: The camera or rig file's name, and whether it gives the calibration's uncertainty.
    camera_file: str = ""
    calibration_known: bool = False


#: ``progress(images_done, images_total, images_measured)`` after each position.
ProgressHook = Callable[[int, int, int], None]


def run_vision_campaign(
    campaign_dir: str | Path,
    *,
    workers: int = 1,
    method: str = "compliance",
    progress: ProgressHook | None = None,
    allow_outside: bool = False,
    dask: str | None = None,
    send_images: bool = False,
) -> RunSummary:
    """Run a vision campaign: measure every position, identify K, fit the model.

    Parameters
    ----------
    campaign_dir : path
        Directory holding ``campaign.toml``.
    workers : int
        Processes measuring positions in parallel (1: in this process); with
        ``dask="local"``, the local cluster's worker processes.
    method : str
        Identification method (see :func:`stiffmap.identify.identify_stiffness`).
    progress : callable, optional
        ``progress(images_done, images_total, images_measured)`` after each
        position (reused positions count as done but not as measured).
    allow_outside : bool
        Let ``campaign.toml`` name files outside the campaign directory
        (``stiffmap run --allow-outside-paths``; :mod:`stiffmap.campaign.paths`).
    dask : str, optional
        Measure on a Dask cluster (:mod:`stiffmap.parallel`): ``"local"`` or a scheduler's
        address. Its workers read the images from the campaign directory when they see it
        at the same path (shared storage), else this process sends each position's files
        with its task. The database is written by this process only, as without Dask.
    send_images : bool
        With ``dask``: send the images to the workers even when they see the campaign
        directory (shared storage slower than the network to this machine).

    Returns
    -------
    RunSummary
        ``failures`` lists every image, position or step that failed (the run
        goes on past them).

    Raises
    ------
    InputError
        When nothing can be done: no or bad campaign.toml, camera file missing or
        malformed, a file named outside the campaign directory, a Dask scheduler that
        cannot be reached or has no worker.
    """
    t_start = time.perf_counter()
    campaign = _read_campaign(campaign_dir, method, allow_outside)  # plan: the spec's positions and images
    summary = _new_summary(campaign, Backend(workers=workers, dask=dask))
    with contextlib.ExitStack() as stack:  # a cluster first: an address that does not answer stops here
        backend = stack.enter_context(connected(Backend(workers=workers, dask=dask)))
        store = stack.enter_context(Store(campaign.db))
        run_id = store.begin_run({"workers": workers, "method": method, "dask": dask})
        work = _plan_work(store, campaign)  # plan: what the database holds, what is left to do
        tally = _Tally(summary, sum(len(t.images) for t in campaign.tasks), progress)
        for task in campaign.tasks:  # images unchanged: derive again when the parameters changed
            if task.index in work.stored:
                problems = _derive_and_persist(store, campaign, work, task, None)
                tally.position_done(task, None, problems)
        _measure_new(store, campaign, work, backend, tally, send_images)
        if backend.cluster is not None:
            summary.notes.extend(backend.cluster.events)
        failures, notes = _rig_checks(store, campaign)
        summary.failures.extend(failures)
        summary.notes.extend(notes)
        failures, info = campaign_flags(store, campaign.spec)
        summary.failures.extend(failures)
        summary.info.extend(info)
        summary.failures.extend(fit_and_evaluate_model(store, campaign.spec, campaign.root, summary.info))
        summary.wall_seconds = time.perf_counter() - t_start
        store.end_run(run_id, "done", {"failures": len(summary.failures)})
    return summary


def _new_summary(campaign: _Campaign, backend: Backend) -> RunSummary:
    """The run's summary before it measures: the campaign, its images not found, the backend."""
    summary = RunSummary(
        campaign=campaign.spec.name,
        positions=len(campaign.tasks),
        db=str(campaign.db),
        camera_file=campaign.camera_path.name,
        calibration_known=campaign.rig.calibration_cov is not None,
    )
    for t in campaign.tasks:
        for rel in t.missing:
            summary.failures.append(f"{rel}: image not found (position {t.index})")
    summary.backend = backend.describe()
    return summary


def _measure_new(
    store: Store, campaign: _Campaign, work: _Work, backend: Backend, tally: _Tally, send_images: bool
) -> None:
    """Measure the positions left to measure (on a cluster: the images sent to its workers, or
    read by them when they see the campaign directory), deriving and persisting each as it comes;
    a position whose task failed is named in the summary and the run goes on."""
    summary = tally.summary
    send = send_images or None
    if backend.cluster is not None and work.to_measure:
        if send is None:
            send = not workers_see_images(backend.cluster, campaign.context, work.to_measure)
        summary.backend += (
            "; images sent to the workers by this process"
            if send
            else "; images read by the workers from the campaign directory (shared storage)"
        )
    measuring = measure_positions(campaign.context, work.to_measure, backend, send_files=send)
    with contextlib.closing(measuring):
        for task, rows in measuring:  # measured: derive and persist each position as it comes
            if isinstance(rows, str):  # the task failed (a bug; dead workers), named; the run goes on
                why = rows
                summary.failures.append(f"position {task.index}: {why}")
                _persist_lost(store, work, task, why)
                tally.position_lost(task)
                continue
            problems = _derive_and_persist(store, campaign, work, task, rows)
            tally.position_done(task, rows, problems)


def _rig_checks(store: Store, campaign: _Campaign) -> tuple[list[str], list[str]]:
    """A rig's cameras that measured nothing or disagree (failures), or missed some image sets
    (notes), over the campaign's image sets (:mod:`stiffmap.campaign.rig_checks`)."""
    if campaign.spec.cameras is None:
        return [], []
    images = {rel for t in campaign.tasks for rel in t.images}
    rows = [(r.status, r.per_camera) for r in store.measurement_rows() if r.image in images]
    return rig_failures(rows, tuple(campaign.rig.names), campaign.camera_path.name)


# ------------------------------------------------------------------------ plan


@dataclass(frozen=True)
class _Campaign:
    """A vision campaign as a run sees it: its directory, spec, camera, loads, positions, method."""

    root: Path
    spec: CampaignSpec
    camera_path: Path
    rig: Rig
    loads: list[LoadCase]
    tasks: list[PositionTask]
    context: MeasureContext
    method: str

    @property
    def db(self) -> Path:
        return self.root / DB_NAME


def _read_campaign(campaign_dir: str | Path, method: str, allow_outside: bool = False) -> _Campaign:
    """Read the spec and the camera and plan the positions; InputError when nothing can be done."""
    root = Path(campaign_dir).resolve()
    spec = load_spec(root)
    if spec.kind != "vision":
        raise InputError(
            f"{root / 'campaign.toml'}: kind = {spec.kind!r}: use 'stiffmap run' on vision campaigns"
        )
    camera_path, rig = read_cameras(spec, root, allow_outside=allow_outside)
    try:
        loads = spec.loads.resolve(spec.g)
        tasks = plan(spec, root, allow_outside=allow_outside, cameras=rig.names if spec.cameras else ())
    except InputError:
        raise
    except ValueError as e:
        raise InputError(str(e), source=str(root / "campaign.toml")) from None
    if tasks and all(len(t.missing) == len(t.images) for t in tasks):
        raise InputError(
            f"no image found: none of the {sum(len(t.images) for t in tasks)} files that [images] "
            f"names exists (e.g. {tasks[0].images[0]!r}, from unloaded = {spec.images.unloaded!r}); "
            "check the patterns and the image folder",
            source=str(root / "campaign.toml"),
        )
    context = MeasureContext.from_spec(spec, root, rig)
    return _Campaign(root, spec, camera_path, rig, loads, tasks, context, method)


def cameras_path(spec: CampaignSpec, root: Path, *, allow_outside: bool = False) -> Path:
    """The campaign's camera file (``camera.file``) or rig file (``cameras.rig``); InputError when
    it leads outside the campaign directory (unless ``allow_outside``)."""
    if spec.cameras is None:
        return campaign_file(root, spec.camera.file, "camera.file", allow_outside=allow_outside)
    return campaign_file(root, spec.cameras.rig, "cameras.rig", allow_outside=allow_outside)


def read_cameras(spec: CampaignSpec, root: Path, *, allow_outside: bool = False) -> tuple[Path, Rig]:
    """The campaign's camera file and its cameras: ``[camera]``'s camera (a rig of one camera) or
    ``[cameras]``'s rig. InputError naming the file, or the key of ``campaign.toml``."""
    path = cameras_path(spec, root, allow_outside=allow_outside)
    if spec.cameras is None:
        try:
            return path, Rig.single(load_camera(path))
        except InputError as e:
            raise InputError(
                f"{e.detail} (the camera file that camera.file in {SPEC_NAME} names)", source=e.source
            ) from None
    try:
        rig = load_rig(path)
    except InputError as e:
        raise InputError(
            f"{e.detail} (the rig file that cameras.rig in {SPEC_NAME} names)", source=e.source
        ) from None
    names = spec.cameras.names
    if names is not None and sorted(names) != sorted(rig.names):
        raise InputError(
            f"key 'cameras.names': {names} are not the cameras of {path.name} ({list(rig.names)})",
            source=str(root / SPEC_NAME),
        )
    return path, rig


@dataclass
class _Work:
    """What the database already holds for a run, and what is left to do.

    Attributes
    ----------
    measure_hash, derive_hash : str
        Hashes of the measurement parameters (image -> poses) and of the
        derivation parameters (poses -> K).
    inputs_hash : dict of int to str
        Per position, the hash of everything its results depend on.
    stored : dict of int to dict of str to ImageRow
        The stored image rows of the positions not to be measured again.
    to_measure : list of PositionTask
    """

    measure_hash: str
    derive_hash: str
    inputs_hash: dict[int, str] = field(default_factory=dict)
    stored: dict[int, dict[str, ImageRow]] = field(default_factory=dict)
    to_measure: list[PositionTask] = field(default_factory=list)


def _plan_work(store: Store, campaign: _Campaign) -> _Work:
    """Hash the parameters and every image; keep the measurements whose inputs are unchanged."""
    ctx = campaign.context
    spec = campaign.spec
    mphash = params_hash(
        {
            "camera": store.sha256(campaign.camera_path),
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
            "method": campaign.method,
            "point": list(spec.targets.mobile.point_mm),
            "pairing": spec.images.pairing,
            "revision": DERIVATION_REVISION,
            "fixed2base": ctx.fixed2base,
            "forces": forces_matrix(campaign.loads),
            "force_cov": force_covariances(campaign.loads),
        }
    )
    work = _Work(mphash, dphash)
    with store.transaction():
        # Positions no longer in campaign.toml leave the results (indices run 1..n).
        store.delete_positions_after(len(campaign.tasks))
        for t in campaign.tasks:
            shas = {rel: _image_sha(store, campaign, t, rel) for rel in t.images if rel not in t.missing}
            work.inputs_hash[t.index] = params_hash(
                {"derive": dphash, "xyz": list(t.xyz), "images": shas, "missing": t.missing}
            )
            prev = {r.image: r for r in store.measurement_rows(t.index)}
            complete = all(
                rel in prev and prev[rel].sha256 == sha and prev[rel].params_hash == mphash
                for rel, sha in shas.items()
            )
            if complete:
                work.stored[t.index] = {rel: _image_row_from_db(prev[rel]) for rel in shas}
            else:
                work.to_measure.append(t)
    return work


# ---------------------------------------------------------- derive, persist


def _derive_and_persist(
    store: Store, campaign: _Campaign, work: _Work, task: PositionTask, measured: list[ImageRow] | None
) -> list[str] | None:
    """Derive a position's results and write them with its measurements, in one transaction.

    ``measured`` is None for a position not measured again: its stored results
    are kept when they were derived from the same inputs.

    Returns
    -------
    list of str or None
        The derivation's problems; None when the stored results were kept.
    """
    inputs_hash = work.inputs_hash[task.index]
    if measured is None and store.stiffness_inputs_hash(task.index) == inputs_hash:
        return None
    rows = work.stored[task.index] if measured is None else {r.image: r for r in measured}
    derived = derive_position(
        task,
        rows,
        campaign.loads,
        campaign.spec,
        campaign.method,
        inputs_hash,
        work.derive_hash,
        calibration_cov=campaign.rig.calibration_cov,
    )
    with store.transaction():
        store.save_position(
            task.index,
            measurements=None
            if measured is None
            else [_measurement_row(store, campaign, work, task, r) for r in measured],
            displacements=derived.displacements,
            repeat_stats=derived.repeat_stats,
            stiffness=derived.stiffness,
        )
    return derived.problems


def _persist_lost(store: Store, work: _Work, task: PositionTask, why: str) -> None:
    """Record a position whose measurement failed as a whole: a failed ``stiffness`` row saying why.

    Its stored ``measurements`` rows (if any) are kept: they are incomplete, so the next run
    measures it again.
    """
    x, y, z = task.xyz
    row = {
        "position": task.index,
        "x": x,
        "y": y,
        "z": z,
        "status": "failed",
        "error": why,
        "inputs_hash": "lost",
        "params_hash": work.derive_hash,
        "version": __version__,
    }
    with store.transaction():
        store.save_position(task.index, displacements=[], repeat_stats=[], stiffness=row)


def _measurement_row(
    store: Store, campaign: _Campaign, work: _Work, task: PositionTask, r: ImageRow
) -> dict[str, Any]:
    """The ``measurements`` row of one measured image."""
    ctx = campaign.context
    return {
        "image": r.image,
        "position": task.index,
        "board_set": f"{ctx.mobile}|{ctx.fixed}",
        "sha256": _image_sha(store, campaign, task, r.image),
        "params_hash": work.measure_hash,
        "version": __version__,
        "status": "ok" if r.ok else "failed",
        "error": r.error,
        "mobile2cam": to_json(r.mobile2cam),
        "mobile_cov": to_json(r.mobile_cov),
        "fixed2cam": to_json(r.fixed2cam),
        "fixed_cov": to_json(r.fixed_cov),
        "mobile_cal_jac": to_json(r.mobile_cal_jac),
        "fixed_cal_jac": to_json(r.fixed_cal_jac),
        "mobile2base": None,
        "base_cov": None,
        "rms_px": r.rms_px,
        "n_corners": r.n_corners,
        "tracked": int(r.tracked),
        "seconds": r.seconds,
        "per_camera": None if r.cameras is None else json.dumps(r.cameras),
    }


def _image_sha(store: Store, campaign: _Campaign, task: PositionTask, image: str) -> str:
    """SHA-256 of an image, or of an image set's files (one per camera; a missing one said)."""
    files = task.files(image)
    if len(files) == 1 and not task.cameras:
        return store.sha256(campaign.root / image)
    parts = []
    for c, f in zip(task.cameras, files, strict=True):
        p = campaign.root / f
        parts.append(f"{c}:{store.sha256(p) if p.is_file() else 'missing'}")
    return hashlib.sha256("|".join(parts).encode()).hexdigest()


def _image_row_from_db(r) -> ImageRow:
    """The :class:`ImageRow` of a stored ``measurements`` row."""
    return ImageRow(
        image=r.image,
        ok=r.status == "ok",
        error=r.error,
        mobile2cam=r.mobile2cam,
        mobile_cov=r.mobile_cov,
        fixed2cam=r.fixed2cam,
        fixed_cov=r.fixed_cov,
        mobile_cal_jac=r.mobile_cal_jac,
        fixed_cal_jac=r.fixed_cal_jac,
        rms_px=r.rms_px,
        n_corners=r.n_corners,
        tracked=bool(r.tracked),
        seconds=r.seconds or 0.0,
        cameras=r.per_camera or None,
    )


class _Tally:
    """The run's counts and progress, position after position."""

    def __init__(self, summary: RunSummary, total: int, progress: ProgressHook | None) -> None:
        self.summary = summary
        self.total = total
        self.progress = progress
        self.done = 0
        self.measured_images = 0

    def position_done(
        self, task: PositionTask, measured: list[ImageRow] | None, problems: list[str] | None
    ) -> None:
        """Count a finished position.

        ``measured``: its images, when measured in this run; ``problems``: those of its
        derivation, None when its stored results were kept.
        """
        s = self.summary
        if measured is None:
            if problems is None:
                s.reused += 1
            else:
                s.rederived += 1
        s.failures.extend(problems or [])
        if measured is not None:
            s.measured += 1
            s.images += len(measured)
            s.image_seconds += sum(r.seconds for r in measured)
            for r in measured:
                if not r.ok:
                    why = r.error or "not measured"
                    named = why.split(": ", 1)[0].endswith(r.image)  # the error names the image already
                    s.failures.append(why if named else f"{r.image}: {why}")
            self.measured_images += len(task.images)
        self.done += len(task.images)
        if self.progress is not None:
            self.progress(self.done, self.total, self.measured_images)

    def position_lost(self, task: PositionTask) -> None:
        """Count a position whose measurement failed as a whole (no progress report)."""
        self.done += len(task.images)


# ---------------------------------------------------------------------- model


def fit_and_evaluate_model(
    store: Store, spec: CampaignSpec, root: Path, notes: list[str] | None = None
) -> list[str]:
    """Evaluate the campaign's model at every position, fit it to the measurements, store both;
    the problems (failures) returned, what the fit accounted for (its ``info``: an extra noise
    estimated) appended to ``notes``.

    A robot kind of parameters such as the Delta's or a robot described by its legs is
    fitted to the measured K (:func:`~stiffmap.models.fit.fit_stiffness`); a kind of joint
    stiffnesses (``joint_params``: a URDF robot's) to the measured displacements themselves
    (:func:`~stiffmap.models.joint_fit.fit_joint_compliances`: linear in the joint
    compliances, translations and rotations with their covariances); a robot whose platform
    turns (a ``dim = 6`` legs TOML) to the measured 6-DOF displacements too
    (:func:`~stiffmap.campaign.platform.fit_platform`), its K at each position the K of the
    loads hung at ``loads.point_mm`` with the platform at its pose (``positions.poses``, or level).
    """
    problems: list[str] = []
    name = spec.robot.model
    kind = spec.robot.kind
    if kind is None:
        return problems
    if kind.dim is not None and kind.dim != 3:
        problems.append(f"robot model {name!r} has no 3D stiffness for a vision campaign; model step skipped")
        return problems
    try:
        model = campaign_model(spec, root)
    except ValueError as e:  # InputError too: it names the file or the key
        where = "robot model" if isinstance(e, InputError) else "campaign.toml robot.params"
        problems.append(f"{where}: {e}")
        return problems
    six = is_platform(model)
    if why := _unusable(model, spec, six):
        return [*problems, why]
    rows = store.stiffness_rows()
    if not rows:
        return problems
    pts = np.array([[r.x, r.y, r.z] for r in rows], dtype=float)
    ok = [r for r in rows if r.status == "ok"]
    disp = store.displacement_rows(only_ok=True) if kind.joint_params or six else []
    ihash = _model_inputs_hash(spec, pts, ok, disp)
    fit_row: dict[str, Any] = {
        "name": "stiffness",
        "model": name,
        "inputs_hash": ihash,
        "version": __version__,
        "robot": to_json(robot_fingerprint(spec, root)),
    }
    if kind.joint_params:  # joint stiffnesses: fitted to the measured displacements themselves
        fitted = _fit_joints(model, spec, rows, disp, fit_row, problems, notes)
    elif six:  # a platform that turns: its legs fitted to the measured displacements too
        fitted = _fit_platform(model, spec, rows, disp, fit_row, problems, notes)
    else:
        fitted = _fit_to_measured(model, ok, spec, fit_row, problems)
    mm = platform_map(fitted, _poses(spec, rows), _lever(spec)) if six else fitted.evaluate(pts)
    store.save_model_stiffness(fit_row, _model_rows(rows, mm, name, ihash, problems))
    return problems


def _model_inputs_hash(spec: CampaignSpec, pts: np.ndarray, ok: list, disp: list) -> str:
    """The hash of what the model step used: the model, its parameters and robot, the positions
    (and orientations), the measured K and displacements."""
    return params_hash(
        {
            "model": spec.robot.model,
            "params": spec.robot.params,
            "robot": spec.robot.model_dump(exclude={"params"}),
            "xyz": pts.tolist(),
            **_turned(spec),  # level: the hash as before
            "K": [r.K for r in ok],
            "d": [(d.position, d.load, d.repeat, d.d, d.cov) for d in disp],
        }
    )


def _model_rows(rows: list, mm, name: str, ihash: str, problems: list[str]) -> list[dict]:
    """The model's stiffness at each position, as stored; a position outside the model is
    appended to ``problems``."""
    per_position = []
    for r, K, valid, reason, det, lam in zip(
        rows, mm.K, mm.valid, mm.reasons, mm.det, mm.min_principal, strict=True
    ):
        per_position.append(
            {
                "position": r.position,
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
            where = f"({r.x:g}, {r.y:g}, {r.z:g})"
            problems.append(f"position {r.position} {where}: outside the model: {reason}")
    return per_position


def _turned(spec: CampaignSpec) -> dict:
    """``{"rpy_deg": [...]}``: the orientations of ``positions.poses`` (empty without)."""
    deg = None if spec.positions is None else spec.positions.orientations_deg()
    return {} if deg is None else {"rpy_deg": deg.tolist()}


def _unusable(model, spec: CampaignSpec, six: bool) -> str:
    """Why a vision campaign cannot use ``model`` ('' when it can): planar, or held level
    while ``positions.poses`` turn its platform."""
    name, turned = spec.robot.model, _turned(spec)
    if model.dim != 3 and not six:
        return f"robot model {name!r} is planar: it has no 3D stiffness for a vision campaign"
    if not six and turned:
        return (
            f"campaign.toml positions.poses: robot model {name!r} holds its platform level (a dim = 3 "
            "legs TOML); give a dim = 6 TOML or the positions as 'list'. Model step skipped"
        )
    return ""


def _poses(spec: CampaignSpec, rows: list) -> np.ndarray:
    """The platform's poses (n, 6; rad) at the rows' positions (``positions.poses``, or level)."""
    return campaign_poses(spec, [[r.x, r.y, r.z] for r in rows], [r.position for r in rows])


def _lever(spec: CampaignSpec) -> np.ndarray:
    """Where the loads act from the tool point (``loads.point_mm``), mm."""
    return np.asarray(spec.loads.point_mm or (0.0, 0.0, 0.0), dtype=float)


def _fit_platform(
    model, spec: CampaignSpec, rows: list, disp: list, fit_row: dict, problems: list[str], notes=None
):
    """A platform that turns with its parameters fitted to the measured 6-DOF displacements
    (``model`` when the fit fails); the fit's columns (or its failure) into ``fit_row``."""
    try:
        if not disp:
            raise InputError("no measured displacement to fit the legs' stiffnesses to")
        loads = spec.loads.resolve(spec.g)
        at = {r.position: i for i, r in enumerate(rows)}
        keep = [d for d in disp if d.position in at and d.load <= len(loads)]
        if not keep:
            raise InputError("no measured displacement at a campaign position")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fit = fit_platform(
                model,
                _poses(spec, rows),
                [at[d.position] for d in keep],
                [loads[d.load - 1].force for d in keep],
                _lever(spec),
                np.array([d.d for d in keep], dtype=float),
                np.array([d.cov for d in keep], dtype=float),
                campaign_fitted_names(spec, model),
            )
        problems.extend(f"model fit: {w.message}" for w in caught)
        problems.extend(f"model fit: {n}" for n in fit.notes)
        if notes is not None:
            notes.extend(f"model fit: {n}" for n in fit.info)
        fit_row.update(model_fit_columns(fit, fit.residual_rms_per_pose))
        return fit.model
    except (InputError, ValueError) as e:
        fit_row.update(status="failed", error=str(e))
        problems.append(f"model fit: {e}")
        return model


def _fit_joints(
    model, spec: CampaignSpec, rows: list, disp: list, fit_row: dict, problems: list[str], notes=None
):
    """A URDF robot with its joint stiffnesses fitted to the measured displacements (``model``
    when the fit fails); the fit's columns (or its failure) into ``fit_row``."""
    try:
        if not disp:
            raise InputError("no measured displacement to fit the joint stiffnesses to")
        loads = spec.loads.resolve(spec.g)
        lever = np.asarray(spec.loads.point_mm or (0.0, 0.0, 0.0), dtype=float)
        pts = np.array([[r.x, r.y, r.z] for r in rows], dtype=float)
        ik = model.configurations_for(pts)
        at = {r.position: i for i, r in enumerate(rows)}
        J_rows, W, D, C, cfg, labels = [], [], [], [], [], []
        jac: dict[int, np.ndarray] = {}
        for d in disp:
            i = at.get(d.position)
            if i is None or not ik.reachable[i] or d.load > len(loads):
                continue
            if i not in jac:  # every joint spring's column: the coordinates', a mimic joint's
                jac[i] = model.spring_jacobians(ik.q[i])[0]
            F = loads[d.load - 1].force
            J_rows.append(jac[i])
            W.append(np.concatenate([F, np.cross(lever, F)]))
            D.append(d.d)
            C.append(d.cov)
            cfg.append(i)
            labels.append(loads[d.load - 1].label)
        if not D:
            raise InputError("no measured displacement at a position the robot model reaches")
        fitted_names = campaign_fitted_names(spec, model)
        # A parameter not fitted is held: a joint's compliance 1/k, a flexible link's 1/p.
        fixed = {k: 1.0 / v for k, v in model.params().items() if k not in fitted_names}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fit = fit_joint_compliances(
                np.array(J_rows),
                np.array(W),
                np.array(D),
                np.array(C),
                joint_names=model.joint_param_names(),
                fit=fitted_names,
                fixed=fixed,
                config_index=np.array(cfg),
                labels=labels,
                extra_noise=True,
                links=model.link_columns(ik.q[np.array(cfg)]) if model.links else (),
            )
        problems.extend(f"model fit: {w.message}" for w in caught)
        problems.extend(f"model fit: {n}" for n in fit.notes)
        if notes is not None:
            notes.extend(f"model fit: {n}" for n in fit.info)
        names = list(fit.names)  # the joints', then the links' parameters
        fitted = model.with_params(**{k: float(fit.stiffness[names.index(k)]) for k in fitted_names})
        idx = [names.index(k) for k in fit.fitted]  # joint order, as fit.covariance
        with np.errstate(divide="ignore"):
            dk_dc = -1.0 / fit.compliance[idx] ** 2  # k = 1/c: the stiffnesses' covariance
        fit_row.update(
            status="ok",
            error=None,
            params=to_json({k: float(fit.stiffness[i]) for k, i in zip(fit.fitted, idx, strict=True)}),
            std=to_json({k: float(fit.stiffness_std[i]) for k, i in zip(fit.fitted, idx, strict=True)}),
            cov=to_json(fit.covariance * np.outer(dk_dc, dk_dc)),
            residuals=to_json(fit.residual_rms_per_config),
            condition=float(fit.condition),
            dof=int(fit.dof),
        )
        return fitted
    except (InputError, ValueError) as e:
        fit_row.update(status="failed", error=str(e))
        problems.append(f"model fit: {e}")
        return model


def _fit_to_measured(model, ok: list, spec: CampaignSpec, fit_row: dict, problems: list[str]):
    """The model fitted to the measured K of the ``ok`` stiffness rows (``model`` when the fit fails).

    The fit's columns (or its failure) go into ``fit_row``, its problem into ``problems``.
    """
    if len(ok) < 1:
        fit_row.update(status="failed", error="no measured stiffness to fit")
        return model
    fitted = model
    try:
        mm = model.evaluate(np.array([[r.x, r.y, r.z] for r in ok]))
        good = [r for r, v in zip(ok, mm.valid, strict=True) if v]
        if not good:
            raise InputError("no measured position lies inside the model's workspace")
        K_std = np.array([r.K_std for r in good])
        fit = fit_stiffness(
            model,
            np.array([[r.x, r.y, r.z] for r in good]),
            np.array([r.K for r in good]),
            params=campaign_fitted_names(spec, model),
            # Without residual degrees of freedom a position's K has no standard errors: the
            # fit then weighs every entry alike (and scales the covariance by its residuals).
            K_std=K_std if np.all(np.isfinite(K_std)) and np.all(K_std > 0) else None,
        )
        fitted = fit.model
        fit_row.update(model_fit_columns(fit, fit.residual_rms_per_pose))
        problems.extend(
            f"model fit: {n}" for n in separation_notes(fit.names, fit.estimate, fit.std, fit.correlation)
        )
    except (InputError, ValueError) as e:
        fit_row.update(status="failed", error=str(e))
        problems.append(f"model fit: {e}")
    return fitted
