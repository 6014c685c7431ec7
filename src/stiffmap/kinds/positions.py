"""Positions by name across the robot kinds: the kinds' layouts (``paper48``, ``points22``,
``arm20``), grids and lists of positions from text, for a kind.

The texts are what a user writes (``--grid 200:600:9,20:420:9``, ``--positions paper48``);
errors are ``ValueError`` saying what was expected, without the option's name (the command
line puts it in front).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..models import presets
from ..models.io import read_points
from .registry import ROBOT_KINDS, robot_kind

__all__ = ["position_presets", "preset_points", "positions_from_text", "grid_from_text", "kind_dim"]


def position_presets() -> dict[str, tuple[str, Callable[[], np.ndarray]]]:
    """Every kind's position layouts: name -> (kind, function returning the points)."""
    return {name: (k.name, fn) for k in ROBOT_KINDS.values() for name, fn in k.positions.items()}


def preset_points(name: str) -> np.ndarray:
    """Points of a named layout of any kind; unknown names list the valid ones (ValueError)."""
    table = position_presets()
    key = name.strip().lower()
    if key not in table:
        raise ValueError(f"unknown position preset {name!r}; valid: {', '.join(table)}")
    return np.asarray(table[key][1](), dtype=np.float64)


def _own_preset(text: str, kind: str) -> np.ndarray | None:
    """The layout ``text`` of ``kind`` (None: no layout of that name); ValueError for another kind's."""
    table = position_presets()
    key = text.strip().lower()
    if key not in table:
        return None
    owner, fn = table[key]
    if owner != kind:
        raise ValueError(f"{text}: that preset is for the {owner} model, not {kind}")
    return np.asarray(fn(), dtype=np.float64)


def kind_dim(kind: str, model=None) -> int:
    """The kind's dimension (a model's, for a kind whose description says it)."""
    k = robot_kind(kind)
    return k.dim if k.dim is not None else int(model.dim)


def positions_from_text(text: str, kind: str, dim: int | None = None) -> np.ndarray:
    """Positions from a layout's name, a CSV file, or a list ``x,y,z;x,y,z`` (``x,y;x,y`` in 2-D).

    Parameters
    ----------
    text : str
        A layout of ``kind``; a CSV file (a ``.csv`` name, or any existing file) with columns
        x, y[, z] in mm; or positions in mm, coordinates separated by commas, positions by
        semicolons.
    kind : str
        A robot kind (its layouts and dimension).
    dim : int, optional
        The dimension, for a kind whose description says it.

    Returns
    -------
    ndarray, shape (N, dim), mm

    Raises
    ------
    ValueError
        As ``'text': expected a preset ...`` (the command line puts its option in front), or
        when the layout is another kind's.
    InputError
        Naming the CSV file and what is wrong in it.
    """
    dim = dim or kind_dim(kind)
    preset = _own_preset(text, kind)
    if preset is not None:
        return preset
    if Path(text).suffix.lower() == ".csv" or Path(text).is_file():
        return read_points(text, dim)
    names = ", ".join(robot_kind(kind).positions)
    return presets.positions_from_list(text, dim, f"the {kind} robot", names)


def grid_from_text(text: str, kind: str, dim: int | None = None) -> np.ndarray:
    """Positions from a layout of ``kind`` or a regular grid ``X0:X1:NX,Y0:Y1:NY[,Z0:Z1:NZ]``.

    Raises
    ------
    ValueError
        As :func:`stiffmap.models.presets.grid_points`, or a layout of another kind.
    """
    dim = dim or kind_dim(kind)
    preset = _own_preset(text, kind)
    if preset is not None:
        return preset
    return presets.grid_points(text, dim, ", ".join(robot_kind(kind).positions))
