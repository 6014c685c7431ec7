"""The robot a model fit was fitted to, as a fingerprint kept with the fit (``model_fit.robot``).

``stiffmap run`` fits the campaign's robot model (``[robot]`` of ``campaign.toml``) and keeps the
fit in ``stiffmap.db``. If ``campaign.toml``'s robot is edited afterwards (another kind, other
parameters, another ``tip_frame``), or its URDF or legs file is, the stored parameters belong to
a robot that is no longer the campaign's: drawn on the new one (``stiffmap report``) or used to
correct a program (``stiffmap compensate --from-campaign``), they would be silently wrong.

:func:`robot_fingerprint` is what the fit depends on, one short hash per part (each parameter,
each key of the kind, the bytes of the robot's file and of the files its keys name, the
positions' joint configurations, the load point), so that :func:`robot_changes` can name what
changed since the run. A fit stored without one (a database of schema 3 and before) cannot be
checked: :func:`robot_changes` says nothing about it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..io import to_jsonable
from .spec import SPEC_NAME, CampaignSpec

__all__ = ["robot_fingerprint", "robot_changes", "stale_fit_message"]


def _hash(value: Any) -> str:
    text = json.dumps(to_jsonable(value), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _file_hash(path: Path) -> str:
    """SHA-256 (short) of a file's bytes; ``missing`` or ``folder`` for what is not a file."""
    if path.is_dir():
        return "folder"
    try:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            while block := f.read(1 << 20):
                h.update(block)
        return h.hexdigest()[:16]
    except OSError:
        return "missing"


def _robot_files(spec: CampaignSpec, root: Path) -> dict[str, Path]:
    """The files the robot section names (its description file, the files of its path keys)."""
    kind = spec.robot.kind
    keys = spec.robot.keys
    if kind is None:
        return {}
    out: dict[str, Path] = {}
    if kind.file_key is not None and isinstance(keys.get(kind.file_key), str):
        name = keys[kind.file_key]
        path = Path(root) / name
        builtin = kind.builtin_file(name)
        out[f"robot.{kind.file_key}"] = Path(builtin) if not path.exists() and builtin else path
    for key in kind.path_keys:
        value = keys.get(key)
        names = value if isinstance(value, (list, tuple)) else [value] if isinstance(value, str) else []
        for i, name in enumerate(n for n in names if isinstance(n, str)):
            out[f"robot.{key}" + (f"[{i}]" if isinstance(value, (list, tuple)) else "")] = Path(root) / name
    return out


def robot_fingerprint(spec: CampaignSpec, root: str | Path) -> dict[str, str]:
    """What a campaign's model fit depends on: ``{part: short hash}`` (module docstring).

    The parts are named as ``campaign.toml`` names them (``robot.model``, ``robot.params.kj``,
    ``robot.tip_frame``, ``robot.urdf file``, ``positions.q_deg``, ``loads.point_mm``).
    """
    robot = spec.robot
    parts = {"robot.model": _hash(robot.model), "robot.fit": _hash(robot.fit)}
    parts.update({f"robot.params.{k}": _hash(v) for k, v in robot.params.items()})
    parts.update({f"robot.{k}": _hash(v) for k, v in robot.keys.items()})
    parts.update({f"{k} file": _file_hash(p) for k, p in _robot_files(spec, Path(root)).items()})
    if spec.positions is not None and spec.positions.q_deg is not None:
        parts["positions.q_deg"] = _hash(spec.positions.q_deg)
    kind = robot.kind
    if kind is not None and kind.takes_load_point and spec.loads is not None:
        parts["loads.point_mm"] = _hash(spec.loads.point_mm)
    return parts


def robot_changes(
    stored: Mapping[str, str] | None, spec: CampaignSpec, root: str | Path, fitted: Iterable[str] = ()
) -> list[str]:
    """The parts of the robot that changed since the fit (empty: none, or no stored fingerprint).

    The starting values of the ``fitted`` parameters are left out: the fit replaces them.
    """
    if not isinstance(stored, Mapping) or not stored:
        return []
    now = robot_fingerprint(spec, root)
    ignored = {f"robot.params.{k}" for k in fitted}
    return sorted(k for k in set(stored) | set(now) if k not in ignored and stored.get(k) != now.get(k))


def stale_fit_message(changes: list[str], root: str | Path) -> str:
    """One line: what changed in the robot since the run, and what to do."""
    shown = ", ".join(changes[:6]) + (f" and {len(changes) - 6} more" if len(changes) > 6 else "")
    return (
        f"the fit in stiffmap.db is another robot's: {SPEC_NAME}'s robot changed since the run "
        f"({shown}); run 'stiffmap run {root}' again to fit this one"
    )
