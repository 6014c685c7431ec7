"""Is the platform at rest, and is the image good? Per frame: both boards, their poses, exposure.

:class:`SettleMonitor` looks at each live frame as :mod:`stiffmap.vision` measures a campaign's
images (:class:`~stiffmap.vision.sequence.PoseTracker`: the boards found, or tracked from the
previous frame, and their poses with covariance) and says:

- **found**: both boards found (a board out of view, or partly, is named with the detector's reason);
- **exposure**: on each board's squares, the fraction of saturated pixels (at the top of the
  8-bit range, 255) and of dark ones (at most :data:`DARK_DN`); a board with more than
  ``max_saturated_fraction`` saturated is refused: a clipped white square moves its edges and
  corners;
- **sharpness**: the steepest edges on each board against its contrast, given as the blur of
  an equivalent Gaussian edge, ``sigma = contrast / (sqrt(2 pi) max |gradient|)`` px (about 0.8
  px for a sharp lens; more: defocus or motion blur);
- **settled**: the platform has not moved, beyond the measurement noise, for ``settle_seconds``.

Settled, exactly: over the frames of the last ``settle_seconds`` the mobile board's pose is
compared with their mean: each frame's change ``d = (dt, dr)`` (the perturbation of
``docs/conventions.md``, camera frame) gives ``chi2 = d^T (C + V)^-1 d`` with ``C`` the pose's own
covariance (stiffmap's, without the calibration's share, which is the same in every frame) and
``V = vibration_mm^2 I`` on the translation (the motion a platform shows at rest); the
platform is at rest when every frame's chi2 is below the ``confidence`` quantile of chi2 with
6 degrees of freedom, and settled when that has held for ``settle_seconds``. The fixed board
is tested the same way (without ``V``): a camera that moves is not a settled platform.

Why the camera frame and not the platform's pose in the fixed board's frame: the fixed board
is small and far from the platform, so its orientation noise, times the lever to the platform,
is 10 to 100 times the mobile board's own noise (170 um against 2 um in the demo's scene); the
camera does not move with respect to the base during a capture (the fixed board's test checks
it), so the mobile board's motion in the camera frame is the platform's motion. The pose change
shown is turned into the base frame's axes through the fixed board.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..camera import CameraModel
from ..geometry import rotvec_from_matrix
from ..stats import chi2_ppf
from ..vision.board_plane import detection_mask
from ..vision.detection import Board, BoardDetection, board_label, grid_of
from ..vision.images import check_image, coarse_scales, reduce_image
from ..vision.sequence import PoseTracker

__all__ = ["SettleSettings", "BoardCheck", "FrameCheck", "SettleMonitor", "DARK_DN", "SATURATED_DN"]

#: A pixel at this value or above is saturated (8 bits).
SATURATED_DN = 255
#: A pixel at this value or below counts as dark.
DARK_DN = 5
#: With no board tracked, frames where the quick search misses a board skip the full search but
#: every this many (a board the quick search cannot see is still found).
FULL_SEARCH_EVERY = 10


@dataclass(frozen=True)
class SettleSettings:
    """How a frame is judged.

    Attributes
    ----------
    settle_seconds : float
        How long the platform must stay within the noise, s.
    vibration_mm : float
        Motion of the platform at rest (1 sigma per axis), mm, added to the noise of the test.
    confidence : float
        Quantile of chi2 (6 degrees of freedom) under which a frame's pose is within the noise.
    max_saturated_fraction : float
        Largest share of a board's pixels that may be saturated.
    refine : {"corners", "auto", "photometric"}
        Pose refinement of the live frames (``"corners"``: fast, for a live view; the saved
        images are measured by ``stiffmap run`` with the campaign's own setting).
    """

    settle_seconds: float = 1.0
    vibration_mm: float = 0.001
    confidence: float = 0.999
    max_saturated_fraction: float = 0.001
    refine: str = "corners"

    @property
    def chi2_limit(self) -> float:
        """The chi2 (6 dof) below which a frame's pose is within the noise."""
        return chi2_ppf(self.confidence, 6)


@dataclass(frozen=True)
class BoardCheck:
    """Exposure and sharpness of one board in one frame.

    Attributes
    ----------
    name : {"mobile", "fixed"}
    found : bool
    saturated_fraction, dark_fraction : float
        Shares of the board's pixels (squares) at 255 and at most :data:`DARK_DN`.
    blur_px : float
        Equivalent Gaussian edge blur, px (NaN when not found).
    contrast_dn : float
        98th minus 2nd percentile of the board's pixels, DN.
    """

    name: str
    found: bool
    saturated_fraction: float = float("nan")
    dark_fraction: float = float("nan")
    blur_px: float = float("nan")
    contrast_dn: float = float("nan")


@dataclass(frozen=True)
class FrameCheck:
    """What one frame showed.

    Attributes
    ----------
    timestamp_s : float
    boards : tuple of BoardCheck
        Mobile, then fixed.
    problem : str or None
        Why an image may not be taken from this frame (a board not found, saturated); None if
        it may (once settled).
    chi2 : float
        Largest chi2 of the frames of the trailing window against their mean (NaN without poses).
    chi2_limit : float
    at_rest_s : float
        How long the platform has been within the noise, s.
    settled : bool
        At rest for ``settle_seconds`` and no problem.
    step_mm : ndarray, shape (3,)
        The mobile board's change of position since the previous frame, base axes, mm (NaN
        when not known).
    step_rad : ndarray, shape (3,)
        Its change of orientation (rotation vector), base axes, rad.
    sigma_mm : ndarray, shape (3,)
        1 sigma of the mobile board's position in this frame, base axes, mm.
    mobile2cam : ndarray, shape (4, 4) or None
    """

    timestamp_s: float
    boards: tuple[BoardCheck, ...]
    problem: str | None
    chi2: float
    chi2_limit: float
    at_rest_s: float
    settled: bool
    step_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    step_rad: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    sigma_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    mobile2cam: np.ndarray | None = None

    def figures(self) -> dict:
        """The numbers the capture log keeps for this frame (JSON-ready)."""

        def num(v):
            return None if not math.isfinite(float(v)) else float(v)

        return {
            "timestamp_s": num(self.timestamp_s),
            "chi2_max": num(self.chi2),
            "chi2_limit": num(self.chi2_limit),
            "at_rest_s": num(self.at_rest_s),
            "step_um": [num(1e3 * v) for v in self.step_mm],
            "sigma_um": [num(1e3 * v) for v in self.sigma_mm],
            "boards": {
                b.name: {
                    "saturated_fraction": num(b.saturated_fraction),
                    "dark_fraction": num(b.dark_fraction),
                    "blur_px": num(b.blur_px),
                    "contrast_dn": num(b.contrast_dn),
                }
                for b in self.boards
            },
        }


@dataclass
class _Seen:
    t: float
    mobile: np.ndarray
    mobile_cov: np.ndarray
    fixed: np.ndarray
    fixed_cov: np.ndarray


def _delta(T: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(dt, dr) from ``ref`` to ``T`` (t <- t + dt, R <- Exp(dr) R; camera frame)."""
    return np.concatenate([T[:3, 3] - ref[:3, 3], rotvec_from_matrix(T[:3, :3] @ ref[:3, :3].T)])


def _chi2s(poses: list[np.ndarray], covs: list[np.ndarray], extra: np.ndarray) -> np.ndarray:
    """chi2 of each pose against the poses' mean (translation mean; rotation about the last)."""
    ref = poses[-1]
    d = np.array([_delta(T, ref) for T in poses])
    d = d - d.mean(axis=0)
    out = np.empty(len(poses))
    for i, (di, C) in enumerate(zip(d, covs, strict=True)):
        try:
            out[i] = float(di @ np.linalg.solve(C + extra, di))
        except np.linalg.LinAlgError:
            out[i] = np.inf
    return out


def _frame_problem(boards, labels, m, max_saturated_fraction: float) -> str | None:
    """Why a frame whose boards were found cannot be judged: a board saturated, or seen only
    in part (None: it can)."""
    for b, label in zip(boards, labels, strict=True):
        if b.saturated_fraction > max_saturated_fraction:
            return (
                f"the {label} is saturated ({100 * b.saturated_fraction:.1f} % of its pixels at "
                f"{SATURATED_DN}): lower the exposure time, the gain or the light"
            )
    for name, det in (("mobile", m.mobile_detection), ("fixed", m.fixed_detection)):
        if not det.complete:
            return f"only part of the {name} target is seen ({det.n_corners} corners)"
    return None


def _rest(frames: list[_Seen], vib: np.ndarray, limit: float) -> tuple[float, float]:
    """chi2 of all the frames, and the time at rest: that of the longest trailing run of frames
    within the noise of their own mean (0 when none)."""
    chi2_all = np.nan
    at_rest = 0.0
    for start in range(len(frames)):
        run = frames[start:]
        c_m = _chi2s([f.mobile for f in run], [f.mobile_cov for f in run], vib)
        c_f = _chi2s([f.fixed for f in run], [f.fixed_cov for f in run], np.zeros((6, 6)))
        c = float(max(c_m.max(), c_f.max()))
        if start == 0:
            chi2_all = c
        if c <= limit:
            at_rest = frames[-1].t - run[0].t
            break
    return chi2_all, at_rest


def board_exposure(image: np.ndarray, det: BoardDetection, name: str) -> BoardCheck:
    """Exposure and sharpness on a found board's squares (its quadrilateral, one square past the
    outer inner corners)."""
    quad = detection_mask(det, margin_sq=1.0)
    h, w = image.shape
    x0, y0 = np.floor(quad.min(axis=0)).astype(int)
    x1, y1 = np.ceil(quad.max(axis=0)).astype(int)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1 + 1, w), min(y1 + 1, h)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return BoardCheck(name, True)
    roi = image[y0:y1, x0:x1]
    mask = np.zeros(roi.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(quad - [x0, y0]).astype(np.int32), 1)
    px = roi[mask > 0]
    if px.size == 0:
        return BoardCheck(name, True)
    lo, hi = np.percentile(px, [2, 98])
    f = roi.astype(np.float32)
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    g = np.hypot(gx, gy)[mask > 0]
    gmax = float(np.percentile(g, 99.5))
    contrast = float(hi - lo)
    blur = contrast / (math.sqrt(2 * math.pi) * gmax) if gmax > 0 else float("inf")
    return BoardCheck(
        name,
        True,
        saturated_fraction=float(np.mean(px >= SATURATED_DN)),
        dark_fraction=float(np.mean(px <= DARK_DN)),
        blur_px=float(blur),
        contrast_dn=contrast,
    )


class SettleMonitor:
    """Judge live frames one after the other (see the module docstring).

    Parameters
    ----------
    camera : CameraModel
    mobile_board, fixed_board : Chessboard or CharucoBoard
    fixed2base : array_like, shape (4, 4)
        The fixed board in the base frame (to show the pose change in the base frame's axes).
    settings : SettleSettings
    """

    def __init__(
        self,
        camera: CameraModel,
        mobile_board: Board,
        fixed_board: Board,
        fixed2base,
        settings: SettleSettings | None = None,
    ) -> None:
        self.settings = settings or SettleSettings()
        s = self.settings
        self.tracker = PoseTracker(
            camera, mobile_board, fixed_board, fixed2base, refine=s.refine, refine_fixed="corners"
        )
        self.fixed2base = np.asarray(fixed2base, dtype=np.float64)
        self.labels = (
            f"mobile target ({board_label(mobile_board)})",
            f"fixed target ({board_label(fixed_board)})",
        )
        self.boards = (mobile_board, fixed_board)
        self._tracking = False
        self._quick_misses = 0
        self._window: deque[_Seen] = deque()
        self._vib = np.zeros((6, 6))
        self._vib[:3, :3] = s.vibration_mm**2 * np.eye(3)

    def _quick_missing(self, img: np.ndarray) -> list[str]:
        """The boards a quick search (OpenCV's fast check, on the image reduced to about 900 px,
        then finer) does not find: a frame without a board costs a tenth of a second instead of
        the full search's seconds; the full search still runs on every
        :data:`FULL_SEARCH_EVERY`-th such frame."""
        flags = cv2.CALIB_CB_FAST_CHECK | cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        out = ["mobile", "fixed"]
        for k in coarse_scales(img.shape, None):
            small = reduce_image(img, k)
            for name, board in zip(("mobile", "fixed"), self.boards, strict=True):
                g = grid_of(board)
                if name in out and cv2.findChessboardCorners(small, (g.cols, g.rows), flags=flags)[0]:
                    out.remove(name)
            if not out:
                break
        return out

    def reset(self) -> None:
        """Forget the frames seen (after a load change or a move: the platform is not at rest)."""
        self._window.clear()

    def _quick_miss(self, img: np.ndarray, timestamp_s: float) -> FrameCheck | None:
        """The frame's check when the quick search misses a board (None: search fully); every
        :data:`FULL_SEARCH_EVERY`-th such frame is searched fully all the same."""
        missing = self._quick_missing(img)
        if missing and self._quick_misses % FULL_SEARCH_EVERY != FULL_SEARCH_EVERY - 1:
            self._quick_misses += 1
            self.reset()
            boards = tuple(BoardCheck(n, n not in missing) for n in ("mobile", "fixed"))
            labels = [lb for n, lb in zip(("mobile", "fixed"), self.labels, strict=True) if n in missing]
            why = f"board not found: the {' and the '.join(labels)} not in view (or not recognisable)"
            return FrameCheck(timestamp_s, boards, why, np.nan, self.settings.chi2_limit, 0.0, False)
        self._quick_misses = 0
        return None

    def check(self, image, timestamp_s: float) -> FrameCheck:
        """Judge one frame (a grey or BGR uint8 array) taken at ``timestamp_s`` (s)."""
        s = self.settings
        img = check_image(image)
        limit = s.chi2_limit
        if not self._tracking and (missed := self._quick_miss(img, timestamp_s)) is not None:
            return missed
        m = self.tracker.measure(img, name="live frame")
        self._tracking = m.ok
        if not m.ok:
            self.reset()
            found = (m.mobile is not None, m.fixed is not None)
            boards = tuple(BoardCheck(n, f) for n, f in zip(("mobile", "fixed"), found, strict=True))
            why = (m.error or "").removeprefix("live frame: ")
            return FrameCheck(timestamp_s, boards, f"board not found: {why}", np.nan, limit, 0.0, False)
        boards = (
            board_exposure(img, m.mobile_detection, "mobile"),
            board_exposure(img, m.fixed_detection, "fixed"),
        )
        problem = _frame_problem(boards, self.labels, m, s.max_saturated_fraction)
        prev = self._window[-1] if self._window else None
        seen = _Seen(
            float(timestamp_s),
            m.mobile.board2frame,
            m.mobile.cov_noise,
            m.fixed.board2frame,
            m.fixed.cov_noise,
        )
        R = self.fixed2base[:3, :3] @ m.fixed.board2frame[:3, :3].T  # cam axes -> base axes
        sigma = np.sqrt(np.clip(np.diag(R @ m.mobile.cov_noise[:3, :3] @ R.T), 0, None))
        step_mm = step_rad = np.full(3, np.nan)
        if prev is not None:
            d = _delta(seen.mobile, prev.mobile)
            step_mm, step_rad = R @ d[:3], R @ d[3:]
        if problem is not None:
            self.reset()
            return FrameCheck(
                timestamp_s, boards, problem, np.nan, limit, 0.0, False, step_mm, step_rad, sigma, seen.mobile
            )
        w = self._window
        w.append(seen)
        tol = 1e-6
        while w and w[0].t < seen.t - s.settle_seconds - tol:
            w.popleft()
        chi2_all, at_rest = _rest(list(w), self._vib, limit)
        settled = at_rest >= s.settle_seconds - tol
        return FrameCheck(
            timestamp_s,
            boards,
            None,
            chi2_all,
            limit,
            at_rest,
            settled,
            step_mm,
            step_rad,
            sigma,
            seen.mobile,
        )
