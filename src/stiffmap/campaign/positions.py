"""The plan of a vision campaign: its robot positions, their load pairs and image files.

:func:`plan` turns ``campaign.toml`` into one :class:`PositionTask` per robot
position (1-based indices, acquisition order): the images to measure, the
unloaded/loaded pairs of every load case and repeat, and the images that are
missing on disk (the run names them and goes on).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .spec import CampaignSpec

__all__ = ["Pair", "PositionTask", "plan"]


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
