"""Render a planned campaign's images to files, in a pool of processes, with their true corners.

:func:`render_campaign_images` renders every :class:`~stiffmap.sim.testbed.ImageJob`
of a :class:`~stiffmap.sim.testbed.CampaignPlan` (:func:`~stiffmap.sim.testbed.render_job`),
writes each image atomically to ``out_dir / job.file`` and returns every image's
true board poses and corner pixels; :func:`render_calibration_images` does the same for
the calibration views (:mod:`stiffmap.sim.calibration_views`). The images do not depend
on the number of processes. What else a simulated campaign directory holds (``campaign.toml``,
``truth.json``) is written by :mod:`stiffmap.campaign.simulated`.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2

from ..errors import InputError
from ..io import atomic_write_bytes
from ..parallel import Backend, Cluster, Lost, connected, map_unordered
from ..rig import camera_path
from .calibration_views import CalibrationView, render_calibration_view
from .render import true_corners
from .testbed import ImageJob, SimConfig, render_job

__all__ = ["render_campaign_images", "render_calibration_images"]

_CTX: dict[str, Any] = {}


def _init_worker(ctx: dict[str, Any]) -> None:
    cv2.setNumThreads(1)
    _CTX.clear()
    _CTX.update(ctx)


def _boards_truth(scene, job: ImageJob, camera: int, rendering=None) -> dict[str, Any]:
    """Per board of one camera's image: its true board2cam and corner pixels."""
    out: dict[str, Any] = {}
    if rendering is not None:
        for t in rendering.targets:
            out[t.name] = {"board2cam": t.board2cam, "corners_px": t.corners_px}
    else:
        cam = scene.cameras[camera][1]
        for tg in scene.targets(job.tcp2base, camera):
            out[tg.name] = {
                "board2cam": tg.board2cam,
                "corners_px": true_corners(cam, tg.board, tg.board2cam),
            }
    return out


def _do_job(job: ImageJob | CalibrationView) -> tuple[dict[str, Any], int, dict[str, bytes]]:
    """Render one job: its truth (with a rig, the first camera's boards and ``cameras``: every
    camera's, by name), the bytes written, and the files themselves when they are sent back
    (a cluster whose workers do not see the output directory) instead of written here."""
    c = _CTX
    files: dict[str, bytes] = {}

    def write(rel: str, data: bytes) -> None:
        if c.get("send_back"):
            files[rel] = data
        else:
            atomic_write_bytes(Path(c["out"]) / rel, data)

    if isinstance(job, CalibrationView):
        data, r = render_calibration_view(c["config"], job)
        write(job.file, data)
        t = r.targets[0]
        truth = {"file": job.file, t.name: {"board2cam": t.board2cam, "corners_px": t.corners_px}}
        return truth, len(data), files
    scene = c["scene"]
    per_camera: dict[str, Any] = {}
    nbytes = 0
    for k, (name, _, _) in enumerate(scene.cameras):
        r = None
        if c["render"]:
            data, r = render_job(scene, c["photometry"], c["seed"], job, c["format"], c["quality"], camera=k)
            write(camera_path(job.file, name), data)
            nbytes += len(data)
        per_camera[name] = _boards_truth(scene, job, k, r)
    out: dict[str, Any] = {"file": job.file, **next(iter(per_camera.values()))}
    if scene.rig is not None:
        out["cameras"] = per_camera
    return out, nbytes, files


def _do_chunk(ctx: dict[str, Any], jobs: list[ImageJob | CalibrationView]):
    return [_do_job(j) for j in jobs]


def render_campaign_images(
    out_dir: str | os.PathLike,
    config: SimConfig,
    jobs: Sequence[ImageJob],
    *,
    workers: int | Backend = 1,
    render_images: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, tuple[dict[str, Any], int]]:
    """Render every job's image to ``out_dir / job.file`` and collect its truth.

    Parameters
    ----------
    out_dir : path-like
    config : SimConfig
        The scene, photometry, seed and image format.
    jobs : sequence of ImageJob
    workers : int or Backend
        Processes rendering images (1: in this process; spawned processes otherwise), or
        where to render (:class:`stiffmap.parallel.Backend`: a Dask cluster). On a cluster
        whose workers do not see ``out_dir``, the images are sent back and written here.
    render_images : bool
        False: the true poses and corners only, no image (in this process).
    progress : callable, optional
        Called as ``progress(done, total)`` at the start and as images finish.

    Returns
    -------
    dict
        Per image file: ``({"file", "fixed": {"board2cam", "corners_px"}, "mobile": {...}},
        bytes written)``.
    """
    ctx = {
        "scene": config.scene,
        "photometry": config.photometry,
        "seed": config.seed,
        "format": config.image_format,
        "quality": config.jpeg_quality,
        "out": str(out_dir),
        "render": bool(render_images),
    }
    return _render_all(ctx, jobs, workers, progress)


def render_calibration_images(
    out_dir: str | os.PathLike,
    config: SimConfig,
    views: Sequence[CalibrationView],
    *,
    workers: int | Backend = 1,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, tuple[dict[str, Any], int]]:
    """Render every calibration view to ``out_dir / view.file`` and collect its truth.

    Parameters
    ----------
    out_dir : path-like
    config : SimConfig
        The camera, photometry, seed and image format.
    views : sequence of CalibrationView
        :func:`~stiffmap.sim.calibration_views.plan_calibration_views`.
    workers : int or Backend
        As :func:`render_campaign_images`.
    progress : callable, optional
        Called as ``progress(done, total)`` at the start and as images finish.

    Returns
    -------
    dict
        Per image file: ``({"file", "calibration": {"board2cam", "corners_px"}}, bytes written)``.
    """
    ctx = {"config": config, "out": str(out_dir), "render": True}
    return _render_all(ctx, views, workers, progress)


def _render_all(
    ctx: dict[str, Any],
    jobs: Sequence[ImageJob | CalibrationView],
    workers: int | Backend,
    progress: Callable[[int, int], None] | None,
) -> dict[str, tuple[dict[str, Any], int]]:
    """Run every job in this process (one worker, or no rendering), in a pool or on a cluster."""
    backend = workers if isinstance(workers, Backend) else Backend(int(workers), start_method="spawn")
    results: dict[str, tuple[dict[str, Any], int]] = {}
    total = len(jobs)
    if progress:
        progress(0, total)
    if not ctx["render"] or (backend.workers <= 1 and not backend.dask):
        backend = Backend(1)
    chunk = 1 if backend.workers <= 1 and not backend.dask else 2
    chunks = [list(jobs[i : i + chunk]) for i in range(0, len(jobs), chunk)]
    with connected(backend) as backend:
        if backend.cluster is not None:
            ctx = {**ctx, "send_back": not _cluster_sees(backend.cluster, Path(ctx["out"]))}
        done_n = 0
        for _, rendered in map_unordered(_do_chunk, ctx, chunks, backend, init=_init_worker):
            if isinstance(rendered, Lost):
                raise InputError(f"rendering stopped: {rendered.reason}; run the simulation again")
            for truth, nbytes, files in rendered:
                for rel, data in files.items():  # sent back by a worker that does not see the folder
                    atomic_write_bytes(Path(ctx["out"]) / rel, data)
                results[truth["file"]] = (truth, nbytes)
                done_n += 1
            if progress:
                progress(done_n, total)
    return results


def _cluster_sees(cluster: Cluster, out: Path) -> bool:
    """Whether the cluster's workers write where this process reads (a probe file in ``out``)."""
    out.mkdir(parents=True, exist_ok=True)
    probe = out / f".stiffmap-probe-{uuid.uuid4().hex}"
    atomic_write_bytes(probe, uuid.uuid4().bytes * 8)
    try:
        return cluster.sees(probe)
    finally:
        probe.unlink(missing_ok=True)
