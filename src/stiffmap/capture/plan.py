"""What a guided capture takes, in order: the campaign's images as steps for the operator.

The images and their names come from the campaign's plan (:func:`stiffmap.campaign.positions.plan`:
``[positions]``, ``[loads]``, ``repeats`` and the ``[images]`` patterns, in the order the run
reads them): position after position, each load case and repeat, the unloaded image (once when
the pattern shares it between load cases) then the loaded one. A :class:`Step` is what the
operator does once -- move the robot, remove or hang a load -- and the image it gives; with
``[capture] frames = N, average = false`` a step gives the N repeats of one image (N settled
frames of one settle), so its images are gathered by position, state and load case.

What to tell the operator about a load comes from the spec's own load cases
(:func:`load_instruction`): "hang 0.500 kg on the +Y pulley", "apply F = (0, 0, -5) N".
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..campaign.positions import plan
from ..campaign.spec import CampaignSpec
from ..errors import InputError
from ..loads import preset as load_preset

__all__ = ["Shot", "Step", "capture_steps", "load_instruction", "load_instructions"]


@dataclass(frozen=True)
class Shot:
    """One image file of the campaign (relative path) and what it shows (1-based indices)."""

    file: str
    position: int
    state: str
    load: int
    repeat: int


@dataclass(frozen=True)
class Step:
    """What the operator does once and the image(s) it gives.

    Attributes
    ----------
    position : int
        1-based.
    xyz_mm : (float, float, float)
        The commanded position.
    state : {"unloaded", "loaded"}
    load : int
        1-based load case (for an unloaded image: the load case it is the reference of).
    shots : tuple of Shot
        One image, or with frames kept as repeats the repeats of one image.
    """

    position: int
    xyz_mm: tuple[float, float, float]
    state: str
    load: int
    shots: tuple[Shot, ...]

    @property
    def files(self) -> tuple[str, ...]:
        return tuple(s.file for s in self.shots)


def capture_steps(spec: CampaignSpec, root: Path, *, group_repeats: bool = False) -> list[Step]:
    """The campaign's images as the operator's steps, in acquisition order.

    ``group_repeats``: one step gives every repeat of an image (frames kept as repeats).

    Raises
    ------
    InputError
        Not a single-camera vision campaign with a fixed target, or the plan's own errors.
    """
    src = str(root / "campaign.toml")
    if spec.kind != "vision":
        raise InputError(
            'stiffmap capture takes the images of a vision campaign (kind = "vision")', source=src
        )
    if spec.cameras is not None:
        raise InputError(
            "stiffmap capture drives one camera; this campaign has a rig ([cameras]): capture each "
            "camera's images with its own program for now",
            source=src,
        )
    if spec.targets.fixed is None:
        raise InputError(
            "stiffmap capture needs the fixed target ([targets.fixed]): it tells a moving camera "
            "from a moving platform",
            source=src,
        )
    group = group_repeats and spec.repeats > 1
    steps: list[Step] = []
    for task in plan(spec, root):
        seen: set[str] = set()
        shots: list[Shot] = []
        for pair in task.pairs:
            for state, rel in (("unloaded", pair.unloaded), ("loaded", pair.loaded)):
                if rel not in seen:
                    seen.add(rel)
                    shots.append(Shot(rel, task.index, state, pair.load, pair.repeat))
        if not group:
            steps.extend(Step(task.index, task.xyz, s.state, s.load, (s,)) for s in shots)
            continue
        order: dict[tuple[str, int], list[Shot]] = {}
        for s in shots:
            order.setdefault((s.state, s.load), []).append(s)
        steps.extend(Step(task.index, task.xyz, st, ld, tuple(g)) for (st, ld), g in order.items())
    return steps


def _direction(u: np.ndarray) -> str | None:
    """``"+Y"`` for a unit vector along an axis, None otherwise."""
    k = int(np.argmax(np.abs(u)))
    if abs(abs(u[k]) - 1.0) > 1e-9:
        return None
    return ("+" if u[k] > 0 else "-") + "XYZ"[k]


def _hang(mass_kg: float, u: np.ndarray) -> str:
    d = _direction(u)
    if d == "-Z":
        return f"hang {mass_kg:.3f} kg straight down from the platform (-Z)"
    if d is not None:
        return f"hang {mass_kg:.3f} kg on the {d} pulley"
    return f"hang {mass_kg:.3f} kg pulling along ({', '.join(f'{v:.3f}' for v in u)})"


def load_instruction(spec: CampaignSpec, load: int) -> str:
    """What the operator does to apply load case ``load`` (1-based), from the spec's load cases."""
    ls = spec.loads
    if ls.preset is not None:
        case = load_preset(ls.preset, g=spec.g)[load - 1]
        f = np.asarray(case.force, dtype=float)
        return _hang(float(np.linalg.norm(f)) / spec.g, f / np.linalg.norm(f))
    c = ls.cases[load - 1]
    if c.force_n is not None:
        text = f"apply F = ({', '.join(f'{v:g}' for v in c.force_n)}) N"
        return text + (f" ({c.label})" if c.label else "")
    d = c.direction
    if isinstance(d, str):
        s = d.strip().lower()
        sign = -1.0 if s.startswith("-") else 1.0
        u = np.zeros(3)
        u["xyz".index(s[-1])] = sign
    else:
        u = np.asarray(d, dtype=float) / np.linalg.norm(d)
    return _hang(float(c.mass_kg), u) + (f" ({c.label})" if c.label else "")


def load_instructions(spec: CampaignSpec) -> list[str]:
    """:func:`load_instruction` of every load case, in order."""
    return [load_instruction(spec, k) for k in range(1, spec.loads.count() + 1)]
