"""Measuring a vision campaign's images: the board poses of every image, one robot position at a time.

A position's images are measured in acquisition order by
:func:`stiffmap.vision.sequence.measure_sequence` (the platform target is
tracked from image to image), in this process or in a worker process
(:func:`measure_positions`). An image that cannot be measured gives an
:class:`ImageRow` with its error; it never stops the position.

With several cameras (``[cameras]``) each "image" is a set of one image per camera: its poses
are the boards' fused poses in the rig frame (the rig frame plays the camera frame downstream),
and the row keeps what each camera gave (``ImageRow.cameras``).
"""

from __future__ import annotations

import contextlib
import functools
import tempfile
import traceback
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import CameraModel
from ..errors import StiffmapWarning
from ..parallel import Backend, Cluster, Lost, connected, map_unordered
from ..rig import Rig
from ..targets import Chessboard
from ..vision.sequence import measure_sequence
from .positions import PositionTask
from .spec import CampaignSpec

__all__ = [
    "MeasureContext",
    "ImageRow",
    "measure_position",
    "measure_positions",
    "task_files",
    "workers_see_images",
]


@dataclass(frozen=True)
class MeasureContext:
    """What a worker needs to measure images (picklable)."""

    root: str
    camera: dict
    mobile: tuple[int, int, float]
    fixed: tuple[int, int, float] | None
    fixed2base: list | None
    refine: str = "auto"
    #: The ``rig.json`` object of a campaign with ``[cameras]`` (None: one camera, ``camera``).
    rig: dict | None = None
    #: The camera or rig file as campaign.toml names it (for the messages).
    camera_file: str = "camera.json"

    @classmethod
    def from_spec(cls, spec: CampaignSpec, root: Path, rig: Rig | CameraModel) -> MeasureContext:
        """The context of a vision campaign: its camera (or rig of cameras), boards and refinement."""
        if isinstance(rig, CameraModel):
            rig = Rig.single(rig)
        t = spec.targets
        mob = Chessboard.parse(t.mobile.board, t.mobile.square_mm)
        fix = Chessboard.parse(t.fixed.board, t.fixed.square_mm) if t.fixed is not None else None
        return cls(
            root=str(root),
            camera=rig.cameras[0].camera.to_dict(),
            rig=rig.to_dict() if spec.cameras is not None else None,
            mobile=(mob.cols, mob.rows, mob.square_mm),
            fixed=None if fix is None else (fix.cols, fix.rows, fix.square_mm),
            fixed2base=t.fixed.fixed2base if t.fixed is not None else None,
            refine=spec.measurement.refine,
            camera_file=spec.camera.file if spec.cameras is None else spec.cameras.rig,
        )


@dataclass
class ImageRow:
    """What one image gave: the board poses (camera frame, mm) with covariances, or an error.

    ``mobile_cov`` and ``fixed_cov`` are the poses' own noise (``BoardPose.cov_noise``),
    independent from image to image; the camera calibration's error, common to every image,
    is carried by the poses' sensitivities to the camera's parameters (``mobile_cal_jac``,
    ``fixed_cal_jac``: ``BoardPose.calibration_jacobian``, (6, n)) and combined with the
    camera's covariance when the position is derived.
    """

    image: str
    ok: bool
    error: str | None = None
    mobile2cam: np.ndarray | None = None
    mobile_cov: np.ndarray | None = None
    fixed2cam: np.ndarray | None = None
    fixed_cov: np.ndarray | None = None
    mobile_cal_jac: np.ndarray | None = None
    fixed_cal_jac: np.ndarray | None = None
    rms_px: float | None = None
    n_corners: int | None = None
    tracked: bool = False
    seconds: float = 0.0
    #: With several cameras: per camera, what it gave (``name``, ``ok``, ``error``, ``rms_px``,
    #: ``n_corners``, ``boards``: which boards it saw).
    cameras: list[dict] | None = None


def measure_position(
    ctx: MeasureContext, task: PositionTask, files: dict[str, Path] | None = None
) -> list[ImageRow]:
    """Measure every existing image of a position (worker process). Never raises for an image.

    ``files``: where to read each file of the task (by its name in the campaign); default
    ``ctx.root / name``.
    """
    camera: CameraModel | Rig
    if ctx.rig is None:
        camera = CameraModel.from_dict(ctx.camera)
    else:
        camera = Rig.from_dict(ctx.rig)
    mobile = Chessboard(*ctx.mobile)
    fixed = Chessboard(*ctx.fixed) if ctx.fixed is not None else None
    root = Path(ctx.root)
    where = (lambda f: files.get(f, root / f)) if files is not None else (lambda f: root / f)
    missing = set(task.missing)
    present = [rel for rel in task.images if rel not in missing]
    # The platform's state in each image, its load case (0: unloaded): the mobile board is
    # tracked from the last image of the same load, where it stood (PoseTracker.measure).
    state = {p.loaded: p.load for p in task.pairs}
    if isinstance(camera, Rig):
        images = [
            {c: where(f) for c, f in zip(task.cameras, task.files(rel), strict=True)} for rel in present
        ]
    else:
        images = [where(rel) for rel in present]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffmapWarning)
        ms = measure_sequence(
            images,
            camera,
            mobile,
            fixed,
            None,
            names=present,
            states=[state.get(rel, 0) for rel in present],
            refine=ctx.refine,
            # The fixed target only orients the displacements, through its mean pose over the
            # position's images: corner poses are precise enough there.
            refine_fixed="corners",
            camera_source=ctx.camera_file,
        )
    rows = []
    for rel, m in zip(present, ms, strict=True):
        per_camera = _per_camera(m) if ctx.rig is not None else None
        if m.error is not None or m.mobile is None:
            rows.append(
                ImageRow(
                    rel,
                    False,
                    m.error or "mobile target not measured",
                    seconds=m.timings.get("total", 0),
                    cameras=per_camera,
                )
            )
            continue
        rms = [p.rms_px for p in (m.mobile, m.fixed) if p is not None]
        n = sum(p.n_corners for p in (m.mobile, m.fixed) if p is not None)
        row = ImageRow(
            rel,
            True,
            mobile2cam=m.mobile.board2frame,
            mobile_cov=m.mobile.cov_noise,
            fixed2cam=None if m.fixed is None else m.fixed.board2frame,
            fixed_cov=None if m.fixed is None else m.fixed.cov_noise,
            mobile_cal_jac=m.mobile.calibration_jacobian,
            fixed_cal_jac=None if m.fixed is None else m.fixed.calibration_jacobian,
            rms_px=float(np.sqrt(np.mean(np.square(rms)))),
            n_corners=int(n),
            tracked=bool(m.tracked),
            seconds=float(m.timings.get("total", 0.0)),
            cameras=per_camera,
        )
        if fixed is not None and m.fixed is None:
            row.ok = False
            row.error = "fixed target not found"
        rows.append(row)
    return rows


def _per_camera(m) -> list[dict]:
    """What each camera of a rig gave for one image set (``ImageMeasurement.views``).

    With two or more cameras on a board, each camera's entry also has how far its own pose of
    the board lies from the fused one (``offset_mm``, ``offset_deg``: the mobile board's, else
    the fixed one's) and ``disagree``: whether the fusion's consistency test refused the
    cameras' poses (:mod:`stiffmap.vision.fuse`; read by :mod:`stiffmap.campaign.rig_checks`).
    """
    offsets = _fusion_offsets(m)
    disagree = bool(m.consistency_warnings)
    out = []
    for v in m.views:
        poses = [p for p in (v.mobile, v.fixed) if p is not None]
        offset = offsets.get(v.camera)
        out.append(
            {
                "name": v.camera,
                "ok": v.error is None,
                "error": v.error,
                "rms_px": float(np.sqrt(np.mean([p.rms_px**2 for p in poses]))) if poses else None,
                "n_corners": int(sum(p.n_corners for p in poses)),
                "boards": [b for b, p in (("mobile", v.mobile), ("fixed", v.fixed)) if p is not None],
                "offset_mm": None if offset is None else offset[0],
                "offset_deg": None if offset is None else offset[1],
                "disagree": disagree,
            }
        )
    return out


def _fusion_offsets(m) -> dict[str, tuple[float, float]]:
    """Each camera's pose of the mobile board (else the fixed) from the fused pose: mm, degrees."""
    for p in (m.mobile, m.fixed):
        views = getattr(p, "views", ())
        if len(views) > 1:
            return {
                v.camera: (
                    float(np.linalg.norm(v.offset[:3])),
                    float(np.degrees(np.linalg.norm(v.offset[3:]))),
                )
                for v in views
            }
    return {}


def _measure_worker(
    ctx: MeasureContext, task: PositionTask, files: dict[str, Path] | None = None
) -> list[ImageRow] | str:
    try:
        return measure_position(ctx, task, files)
    except Exception:  # a bug, not a user error: keep the message, let the run go on
        return "internal error while measuring:\n" + traceback.format_exc()


def _measure_sent(ctx: MeasureContext, sent: tuple[PositionTask, dict[str, bytes]]) -> list[ImageRow] | str:
    """Measure a position whose files came as bytes (a worker that does not see the campaign).

    Each file is written to a temporary folder under a name of its own (the campaign's names
    may be absolute or lead out of the campaign, with ``--allow-outside-paths``), measured,
    and deleted; a file the client could not read is absent, and its image's row says so.
    """
    task, blobs = sent
    with tempfile.TemporaryDirectory(prefix="stiffmap-") as tmp:
        files = {}
        for k, (rel, data) in enumerate(blobs.items()):
            files[rel] = Path(tmp) / f"{k:05d}{Path(rel).suffix}"
            files[rel].write_bytes(data)
        for rel in task_files(task):
            files.setdefault(rel, Path(tmp) / "not sent" / Path(rel).name)
        return _measure_worker(ctx, task, files)


def _read_files(root: Path, task: PositionTask) -> tuple[PositionTask, dict[str, bytes]]:
    """A position's files as bytes, to send with its task (those that cannot be read are left out)."""
    blobs = {}
    for f in task_files(task):
        with contextlib.suppress(OSError):
            blobs[f] = (root / f).read_bytes()
    return task, blobs


def task_files(task: PositionTask) -> list[str]:
    """Every existing file of a position (relative to the campaign; one per camera of a rig)."""
    missing = set(task.missing)
    return [f for rel in task.images if rel not in missing for f in task.files(rel)]


def measure_positions(
    ctx: MeasureContext,
    tasks: list[PositionTask],
    backend: Backend | int,
    *,
    send_files: bool | None = None,
) -> Iterator[tuple[PositionTask, list[ImageRow] | str]]:
    """Measure positions, yielding each as soon as it is done.

    ``backend`` (:class:`stiffmap.parallel.Backend`, or a number of processes) says where:
    this process, a pool of processes, or a Dask cluster. ``send_files``: on a cluster,
    read each position's files here and send them with its task, at most two positions
    per worker in flight (for workers without the campaign directory at the same path);
    None: when :func:`workers_see_images` says so. A position whose measurement failed as
    a whole (a bug, not a user error: an image's problem is its row's error; or a task the
    cluster gave up because its workers kept dying) yields why, in one line, instead of
    its rows. Close the iterator (``contextlib.closing``) to stop the workers when the
    caller stops early.
    """
    if not tasks:
        return
    if isinstance(backend, int):
        backend = Backend(workers=backend)
    with connected(backend) as backend:
        fn, prepare, window = _measure_worker, None, None
        if backend.cluster is not None:
            if send_files is None:
                send_files = not workers_see_images(backend.cluster, ctx, tasks)
            if send_files:
                fn, window = _measure_sent, 2 * backend.cluster.n_workers
                prepare = functools.partial(_read_files, Path(ctx.root))

        results = map_unordered(fn, ctx, tasks, backend, prepare=prepare, window=window)
        with contextlib.closing(results):
            for task, rows in results:
                if isinstance(rows, Lost):
                    rows = f"the position's task was given up: {rows.reason}"
                elif isinstance(rows, str):
                    rows = f"internal error while measuring (a bug): {rows.splitlines()[-1]}"
                yield task, rows


def workers_see_images(cluster: Cluster, ctx: MeasureContext, tasks: list[PositionTask]) -> bool:
    """Whether the cluster's workers read the campaign's images where this process does."""
    for t in tasks:
        files = task_files(t)
        if files:
            return cluster.sees(Path(ctx.root) / files[0])
    return True
