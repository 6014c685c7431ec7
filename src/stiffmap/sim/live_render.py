"""Frames of a static camera in which only some targets move: :func:`~stiffmap.sim.render.render`'s
image, without rendering the static part again for every frame.

A live camera (:mod:`stiffmap.sim.live_camera`) renders frame after frame of one scene in which
the camera, the background and the fixed board stay put and only the platform's board moves.
:class:`FrameRenderer` renders the static targets' patches once, with the sensor's mean signal
and noise sigma of the static image; each frame then renders only the moving targets' patches
(their bounding box widened by the blur's reach, at the supersampled resolution of
:func:`~stiffmap.sim.photometry.blurred_reflectance`, through a :class:`RayWindow` that keeps
the rays of that part of the image), draws the frame's noise over the whole image and rounds
to 8 bits.

The image is the one ``render(camera, [*static, *moving], photometry=..., seed=rng).image``
gives, bit for bit, with the same draws from ``rng``: the same function renders each patch
(:func:`~stiffmap.sim.photometry.target_patch`), the photometry is computed pixel by pixel in
the same float32 operations, and the noise is one draw of the whole image as there. Where the
shortcut does not hold the frame is rendered in full: a moving target inside a static one's
patch (the static patch would show it), a cluttered background (drawn anew for each frame), no
optics blur.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..camera import CameraModel, pixel_rays
from .coverage import UNIFORM_TILE_PX
from .photometry import (
    BLUR_SUPERSAMPLE,
    Photometry,
    _supersampled_camera,
    has_noise,
    noise_sigma,
    patch_bounds,
    sensor_signal,
    target_patch,
)
from .reflectance import Target, target_bbox
from .render import render

__all__ = ["FrameRenderer", "RayWindow"]

#: Fine rows rendered at a time: tiles leave few pixels to work out one by one, and fewer,
#: larger blocks spend less time in the per-call work of the pixels crossed by several lines.
_CHUNK_ROWS = 512


class RayWindow:
    """The rays of a window of a camera's pixels, evaluated once and then sliced.

    :meth:`block` returns what ``pixel_rays(camera).block(rows, cols)`` returns (the spline
    gives each pixel's ray from its own position: a slice of a larger grid is the same, bit
    for bit); a request outside the window moves the window there, ``margin_px`` wider on
    every side.

    Parameters
    ----------
    camera : CameraModel
    margin_px : int
        Pixels added on every side of a window that has to move (room for a target that moves
        a little between frames).
    """

    def __init__(self, camera: CameraModel, margin_px: int = 32) -> None:
        self.rays = pixel_rays(camera)
        self.margin_px = int(margin_px)
        self._box: tuple[int, int, int, int] | None = None  # r0, r1, c0, c1 (end excluded)
        self._rx = self._ry = np.empty((0, 0))
        self.moves = 0

    def cover(self, r0: int, r1: int, c0: int, c1: int) -> None:
        """Make the window hold rows r0..r1-1 and columns c0..c1-1 (pixel indices, may reach
        past the image by the renderer's halo)."""
        b = self._box
        if b is not None and b[0] <= r0 and r1 <= b[1] and b[2] <= c0 and c1 <= b[3]:
            return
        m = self.margin_px
        box = (r0 - m, r1 + m, c0 - m, c1 + m)
        rows = np.arange(box[0], box[1], dtype=np.float64)
        cols = np.arange(box[2], box[3], dtype=np.float64)
        rx, ry = self.rays.block(rows, cols)
        rx.setflags(write=False)
        ry.setflags(write=False)
        self._box, self._rx, self._ry = box, rx, ry
        self.moves += 1

    def block(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays on the grid rows x cols, as :meth:`stiffmap.camera.PixelRays.block`."""
        rows = np.asarray(rows, dtype=np.float64)
        cols = np.asarray(cols, dtype=np.float64)
        r0, c0 = int(rows[0]), int(cols[0])
        if not (
            np.array_equal(rows, np.arange(r0, r0 + rows.size, dtype=np.float64))
            and np.array_equal(cols, np.arange(c0, c0 + cols.size, dtype=np.float64))
        ):
            return self.rays.block(rows, cols)  # not a run of whole pixels: evaluated as asked
        self.cover(r0, r0 + rows.size, c0, c0 + cols.size)
        R0, _, C0, _ = self._box
        i, j = r0 - R0, c0 - C0
        return self._rx[i : i + rows.size, j : j + cols.size], self._ry[i : i + rows.size, j : j + cols.size]


class FrameRenderer:
    """Render frames of one camera in which the targets ``static`` stay put (see the module docstring).

    Parameters
    ----------
    camera : CameraModel
    static : sequence of Target
        The targets that do not move (drawn before the moving ones, as :func:`render` draws a
        list in its order).
    photometry : Photometry, optional
        Default :class:`Photometry` ().

    Attributes
    ----------
    full_frames : int
        Frames rendered in full because the shortcut did not hold (see the module docstring).
    """

    def __init__(self, camera: CameraModel, static, photometry: Photometry | None = None) -> None:
        self.camera = camera
        self.static = list(static)
        for tg in self.static:
            if not isinstance(tg, Target):
                raise ValueError(f"static targets must be Target objects, got {type(tg).__name__}")
        self.photometry = Photometry() if photometry is None else photometry
        ph = self.photometry
        self.full_frames = 0
        self._shortcut = not ph.clutter and ph.blur_px > 0 and BLUR_SUPERSAMPLE > 1
        if not self._shortcut:
            return
        w, h = camera.image_size
        ss = BLUR_SUPERSAMPLE
        self._cam_s = _supersampled_camera(camera, ss)
        self._window = RayWindow(self._cam_s)
        refl = np.full((h, w), float(ph.background), dtype=np.float32)
        self._static_rois = []
        for tg in self.static:
            bounds = patch_bounds(camera, tg, ph.blur_px)
            if bounds is None:
                continue
            R0, R1, C0, C1 = bounds[0]
            self._static_rois.append((C0 * ss, R0 * ss, C1 * ss, R1 * ss))
            (i0, i1, j0, j1), values = target_patch(
                camera,
                self.static,
                tg,
                background=ph.background,
                blur_px=ph.blur_px,
                supersample=ss,
                tile_px=UNIFORM_TILE_PX,
                chunk_rows=_CHUNK_ROWS,
            )
            refl[i0:i1, j0:j1] = values
        self._refl = refl
        self._sig = sensor_signal(refl, camera, ph)
        self._sd = noise_sigma(self._sig, ph) if has_noise(ph) else None
        for a in (self._refl, self._sig, self._sd):
            if a is not None:
                a.setflags(write=False)

    def _static_unchanged(self, moving: list[Target]) -> bool:
        """No moving target falls in a static target's rendered area (which would then show it)."""
        for roi in self._static_rois:
            for tg in moving:
                if target_bbox(self._cam_s, tg.texture(), tg.board2cam, roi) is not None:
                    return False
        return True

    def frame(self, moving, rng: np.random.Generator | None = None) -> np.ndarray:
        """One frame with the targets ``moving`` where they are now.

        Parameters
        ----------
        moving : sequence of Target
        rng : numpy Generator
            The frame's noise source (needed when the photometry has noise); drawn from as
            :func:`render` draws from it.

        Returns
        -------
        ndarray of uint8, shape (h, w) or (h, w, 3)
            ``render(camera, [*static, *moving], photometry=photometry, seed=rng).image``.
        """
        moving = list(moving)
        ph = self.photometry
        if has_noise(ph) and rng is None:
            raise ValueError(
                "FrameRenderer.frame needs a random generator (rng) when the photometry has noise"
            )
        if not self._shortcut or not self._static_unchanged(moving):
            self.full_frames += 1
            return render(self.camera, [*self.static, *moving], photometry=ph, seed=rng).image
        ss = BLUR_SUPERSAMPLE
        targets = [*self.static, *moving]
        patches = []
        for tg in moving:
            bounds = patch_bounds(self.camera, tg, ph.blur_px)
            if bounds is None:
                continue
            R0, R1, C0, C1 = bounds[0]
            # The fine rows and columns of the patch, with the renderer's one-pixel halo.
            self._window.cover(R0 * ss - 1, R1 * ss + 1, C0 * ss - 1, C1 * ss + 1)
            patches.append(
                target_patch(
                    self.camera,
                    targets,
                    tg,
                    background=ph.background,
                    blur_px=ph.blur_px,
                    supersample=ss,
                    rays=self._window,
                    tile_px=UNIFORM_TILE_PX,
                    chunk_rows=_CHUNK_ROWS,
                )
            )
        w, h = self.camera.image_size
        if patches:
            # One box around the moving targets' patches: its reflectance, signal and sigma anew.
            r0 = min(p[0][0] for p in patches)
            r1 = max(p[0][1] for p in patches)
            c0 = min(p[0][2] for p in patches)
            c1 = max(p[0][3] for p in patches)
            refl = self._refl[r0:r1, c0:c1].copy()
            for (i0, i1, j0, j1), values in patches:
                refl[i0 - r0 : i1 - r0, j0 - c0 : j1 - c0] = values
            sig_u = sensor_signal(refl, self.camera, ph, origin=(r0, c0))
        if has_noise(ph):
            # The whole image's noise in one draw, as render() draws it; then signal + sd * noise.
            out = rng.standard_normal((h, w), dtype=np.float32)
            if patches:
                noise_u = out[r0:r1, c0:c1].copy()
            out *= self._sd
            out += self._sig
            if patches:
                out[r0:r1, c0:c1] = noise_u * noise_sigma(sig_u, ph) + sig_u
        else:
            out = self._sig.copy()
            if patches:
                out[r0:r1, c0:c1] = sig_u
        out += np.float32(ph.offset_dn)
        np.rint(out, out=out)
        np.clip(out, 0, 255, out=out)
        raw = out.astype(np.uint8)
        if ph.colour:
            return cv2.cvtColor(raw, cv2.COLOR_BayerBG2BGR_EA)
        return raw
