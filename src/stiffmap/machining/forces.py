"""The cutting force along a toolpath: constant in the base frame, turning with the feed, or per move.

Feed moves (G1, G2, G3) carry the force, rapids (G0) none. Three ways to give it
(:class:`ForceSpec`):

- ``base``: a constant force (FX, FY, FZ) in the base frame (N); the program's axes are
  parallel to the base's (``docs/machining.md``);
- ``feed``: (FT, FN, FZ) in the feed's frame: FT along the horizontal part ``h`` of the
  unit direction of travel (its projection on the XY plane, length 1 for a horizontal
  move), FN across it in that plane (``z x h``, to the left of the travel) and FZ along z
  (the tool axis): ``F = FT h + FN (z x h) + FZ z``. The in-plane force scales with the
  horizontal share of the feed, so it varies continuously along an arc that turns
  vertical (G18, G19) and a plunge carries FZ only;
- ``per_move``: a force at the start and the end of every move (N), linear in between
  (a force file: constant per move; a CSV of points: the rows' forces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .path import Toolpath

__all__ = ["ForceSpec", "force_at"]


@dataclass(frozen=True)
class ForceSpec:
    """How the cutting force is given (module docstring).

    Attributes
    ----------
    mode : str
        ``"base"``, ``"feed"`` or ``"per_move"``.
    value : ndarray, shape (3,), N
        (FX, FY, FZ) for ``base``, (FT, FN, FZ) for ``feed``.
    start, end : ndarray, shape (n, 3), N, or None
        ``per_move``: the force at the start and at the end of each move (base frame).
    """

    mode: str
    value: np.ndarray | None = None
    start: np.ndarray | None = None
    end: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.mode not in ("base", "feed", "per_move"):
            raise ValueError(f"force mode must be base, feed or per_move, got {self.mode!r}")
        if self.mode == "per_move":
            if self.start is None or self.end is None:
                raise ValueError("per_move forces need start and end arrays")
        else:
            v = np.asarray(self.value, dtype=float).reshape(-1)
            if v.size == 2:
                v = np.append(v, 0.0)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f"force must be 2 or 3 finite numbers (N), got {self.value!r}")
            object.__setattr__(self, "value", v)

    @classmethod
    def constant(cls, force) -> ForceSpec:
        """A constant force (FX, FY[, FZ]) in N, base frame."""
        return cls("base", np.asarray(force, dtype=float))

    @classmethod
    def feed_frame(cls, force) -> ForceSpec:
        """(FT, FN[, FZ]) in N in the feed's frame."""
        return cls("feed", np.asarray(force, dtype=float))

    def describe(self) -> str:
        if self.mode == "base":
            return "F = ({:g}, {:g}, {:g}) N, base frame".format(*self.value)
        if self.mode == "feed":
            return "F = ({:g} along the feed, {:g} across it, {:g} along z) N".format(*self.value)
        return "F per move (from a file)"


def force_at(path: Toolpath, spec: ForceSpec, m, s) -> np.ndarray:
    """The force (N, base frame) at parameter ``s`` of moves ``m``; zero on rapids.

    Parameters
    ----------
    path : Toolpath
    spec : ForceSpec
    m : array_like of int, shape (N,)
    s : array_like, shape (N,)

    Returns
    -------
    ndarray, shape (N, 3), N
    """
    m = np.asarray(m, dtype=np.intp)
    s = np.asarray(s, dtype=np.float64)
    if spec.mode == "base":
        F = np.broadcast_to(spec.value, (m.size, 3)).copy()
    elif spec.mode == "per_move":
        F = spec.start[m] + s[:, None] * (spec.end[m] - spec.start[m])
    else:
        et = path.tangent(m, s)
        et[:, 2] = 0.0
        en = np.stack([-et[:, 1], et[:, 0], np.zeros(m.size)], axis=1)
        FT, FN, FZ = spec.value
        F = FT * et + FN * en
        F[:, 2] += FZ
    F[~path.feed[m]] = 0.0
    return F
