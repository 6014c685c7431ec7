"""A model evaluated over many poses in chunks, reporting progress between them.

A robot described by its legs or a URDF solves each pose's inverse kinematics in turn
(about 1.5 ms a pose for the Delta written as legs): ``stiffmap model legs --grid`` over a
million poses takes about 25 minutes. :func:`evaluate_in_chunks` evaluates the same
:class:`~stiffmap.models.base.ModelMap` a chunk of poses at a time (each chunk is one
``evaluate`` call, vectorised where the model is) and calls ``progress(done, total)`` after
each, so the command line can show a progress bar; the map is the one ``evaluate`` gives
over all the poses at once.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from .base import Mechanism, ModelMap

__all__ = ["evaluate_in_chunks", "CHUNK_POSES"]

#: Poses per ``evaluate`` call (vectorised models lose nothing at this size).
CHUNK_POSES = 2000


def _concatenate(maps: list[ModelMap]) -> ModelMap:
    """One map from consecutive maps of the same model (arrays stacked, read-only)."""
    if len(maps) == 1:
        return maps[0]
    values = {}
    for f in dataclasses.fields(ModelMap):
        parts = [getattr(m, f.name) for m in maps]
        if f.name in ("mechanism", "params"):
            values[f.name] = parts[0]
        elif f.name == "reasons":
            values[f.name] = tuple(r for p in parts for r in p)
        elif any(p is None for p in parts):  # an optional array (K6 of a robot that turns): absent
            values[f.name] = None
        else:
            a = np.concatenate(parts, axis=0)
            a.setflags(write=False)
            values[f.name] = a
    return ModelMap(**values)


def evaluate_in_chunks(
    model: Mechanism,
    points,
    progress: Callable[[int, int], None] | None = None,
    *,
    chunk: int = CHUNK_POSES,
) -> ModelMap:
    """``model.evaluate(points)``, a chunk of poses at a time, with progress.

    Parameters
    ----------
    model : Mechanism
    points : array_like, shape (N, dim), mm
    progress : callable, optional
        ``progress(poses_done, poses_total)`` after each chunk (and once before the first).
    chunk : int
        Poses per ``evaluate`` call.

    Returns
    -------
    ModelMap
        As ``model.evaluate(points)``.
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or len(P) <= chunk:
        out = model.evaluate(P)
        if progress is not None:
            progress(len(out), len(out))
        return out
    n = len(P)
    maps = []
    if progress is not None:
        progress(0, n)
    for start in range(0, n, chunk):
        maps.append(model.evaluate(P[start : start + chunk]))
        if progress is not None:
            progress(min(start + chunk, n), n)
    return _concatenate(maps)
