"""The plan of a vision campaign: its robot positions, their load pairs and image files.

:func:`plan` turns ``campaign.toml`` into one :class:`PositionTask` per robot
position (1-based indices, acquisition order): the images to measure, the
unloaded/loaded pairs of every load case and repeat, and the images that are
missing on disk (the run names them and goes on).

With several cameras (``[cameras]``) an "image" is an image set, one file per camera: its
name is the pattern's path with ``{camera}`` kept (:meth:`PositionTask.files` gives the
files); a set is missing when none of its cameras' files is on disk (a set missing for some
cameras only is measured with the others, and the missing ones named).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..rig import camera_path
from .paths import campaign_file
from .robot import campaign_positions
from .spec import SPEC_NAME, CampaignSpec

__all__ = ["Pair", "PositionTask", "plan", "campaign_poses"]


def campaign_poses(spec: CampaignSpec, xyz, numbers) -> np.ndarray:
    """The platform's poses (n, 6: x, y, z mm, roll, pitch, yaw rad) at positions ``xyz``
    (n, 3) mm, numbered ``numbers`` (1-based, campaign.toml's order): the orientations of
    ``positions.poses``, or level.
    """
    P = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    A = np.zeros_like(P)
    deg = None if spec.positions is None else spec.positions.orientations_deg()
    if deg is not None:
        idx = np.asarray(numbers, dtype=int) - 1
        A = np.radians(deg[idx])
    return np.concatenate([P, A], axis=1)


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
    cameras: tuple[str, ...] = ()

    def files(self, image: str) -> tuple[str, ...]:
        """The files of an image (one per camera of a rig; the image itself with one camera)."""
        return tuple(camera_path(image, c) for c in self.cameras) if self.cameras else (image,)


def plan(
    spec: CampaignSpec, root: Path, *, allow_outside: bool = False, cameras: tuple[str, ...] = ()
) -> list[PositionTask]:
    """The positions of a vision campaign with their image files (missing ones listed).

    ``cameras``: the rig's camera names when the campaign has ``[cameras]`` (each image is
    then a set of one file per camera, see the module docstring).

    Raises
    ------
    InputError
        An image name leads outside the campaign directory (unless ``allow_outside``:
        ``stiffmap run --allow-outside-paths``), or the ``[images]`` patterns give one file
        two roles (a loaded image that is also an unloaded one, or one file for two
        positions or two load cases), naming the key and the two uses.
    """
    positions = campaign_positions(spec, root)
    n_loads = len(spec.loads.resolve(spec.g))
    roles: dict[str, tuple[str, int, int, int]] = {}
    resolved: dict = {}  # folders resolved once for all the images
    tasks = []
    for p, xyz in enumerate(positions, start=1):
        pairs, images, missing = [], [], []
        seen: set[str] = set()
        for ld in range(1, n_loads + 1):
            for r in range(1, spec.repeats + 1):
                u = spec.images.path("unloaded", p, ld, r)
                lo = spec.images.path("loaded", p, ld, r)
                _claim(roles, u, ("unloaded", p, ld, r), root)
                _claim(roles, lo, ("loaded", p, ld, r), root)
                pairs.append(Pair(ld, r, u, lo))
                for state, rel in (("unloaded", u), ("loaded", lo)):
                    if rel not in seen:
                        files = [camera_path(rel, c) for c in cameras] if cameras else [rel]
                        for f, c in zip(files, cameras or ("",), strict=True):
                            campaign_file(
                                root,
                                f,
                                f"images.{state}",
                                f"position {p}, load {ld}, repeat {r}" + (f", camera {c}" if c else ""),
                                allow_outside=allow_outside,
                                cache=resolved,
                            )
                        images.append(rel)
                        seen.add(rel)
                        if not any((root / f).is_file() for f in files):
                            missing.append(rel)
        tasks.append(
            PositionTask(
                p,
                (float(xyz[0]), float(xyz[1]), float(xyz[2])),
                tuple(images),
                tuple(pairs),
                tuple(missing),
                tuple(cameras),
            )
        )
    return tasks


def _claim(roles: dict, rel: str, role: tuple[str, int, int, int], root: Path) -> None:
    """Record that ``rel`` is the image of ``role``; InputError when it already has another role.

    An unloaded image may serve every load case (and repeat) of its position; a loaded
    image is one load case and repeat; no file is both.
    """
    prev = roles.setdefault(os.path.normpath(rel), role)
    if prev == role:
        return
    state, p, ld, r = role
    pstate, pp, pld, pr = prev
    if state == pstate == "unloaded" and p == pp:
        return
    where = f"key 'images.{state}'" if state == pstate else "keys 'images.loaded' and 'images.unloaded'"
    raise InputError(
        f"{where}: the patterns name the same file {rel!r} for the {pstate} image of position {pp}, "
        f"load {pld}, repeat {pr} and for the {state} image of position {p}, load {ld}, repeat {r}; "
        "each image has one role (zero-pad or separate the numbers, e.g. p{position:02d}_l{load:02d})",
        source=str(root / SPEC_NAME),
    )
