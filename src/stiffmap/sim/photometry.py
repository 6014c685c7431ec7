"""The image-formation model: optics blur, vignetting, sensor noise and 8-bit quantisation.

:class:`Photometry` describes how the scene's reflectance (:mod:`.reflectance`) becomes
an 8-bit image: :func:`blurred_reflectance` passes it through the optics (a Gaussian
point-spread function, then integration over each pixel, on supersampled target regions),
and :func:`apply_photometry` through the sensor: illumination gain and black level, cos^4
vignetting, shot and read noise from a seeded generator, an optional Bayer colour
filter, rounding. The pieces (:func:`target_patch`, :func:`sensor_signal`, :func:`noise_sigma`)
serve :mod:`.live_render`, which renders again only what moves between a live camera's frames.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import CameraModel
from .reflectance import render_reflectance, target_bbox

__all__ = [
    "Photometry",
    "apply_photometry",
    "blurred_reflectance",
    "BLUR_SUPERSAMPLE",
    "blur_reach_px",
    "patch_bounds",
    "target_patch",
    "has_noise",
    "sensor_signal",
    "noise_sigma",
]


@dataclass(frozen=True)
class Photometry:
    """From scene reflectance to 8-bit pixel values.

    The mean value of a pixel seeing reflectance rho is
    ``offset_dn + 255 gain V rho`` digital numbers (DN), V the vignetting;
    its noise is Gaussian with variance ``read_noise_dn^2 + shot_dn_per_e * signal``
    (photon shot noise, signal = the mean above the black level, in DN).

    Attributes
    ----------
    gain : float
        Fraction of full scale reached by reflectance 1 at the image centre.
    offset_dn : float
        Black level, DN.
    read_noise_dn : float
        Read noise, 1 sigma, DN.
    shot_dn_per_e : float
        Conversion gain, DN per photo-electron (0: no shot noise).
    blur_px : float
        Gaussian blur of the optics, 1 sigma, px: the lens's point-spread
        function plus any defocus (default 0.8 px, a sharp lens on a sensor
        with pixels of a few micrometres; 0: an ideal step edge).
    vignetting : float
        0..1: blend of the cos^4 law of the angle between a pixel's line of sight and
        the optical axis (pinhole angle, distortion neglected; 1: full cos^4 fall-off).
    background : float
        Reflectance of the scene behind the targets.
    clutter : bool
        Random shapes (seeded) in the background instead of a plain one.
    colour : bool
        A colour camera: a Bayer sensor (R at even rows and columns, noise per
        photosite) demosaiced by OpenCV (edge-aware) into BGR, instead of grey.
    white_balance : (float, float, float)
        Gains of the B, G and R photosites of a colour camera.
    """

    gain: float = 0.8
    offset_dn: float = 6.0
    read_noise_dn: float = 0.8
    shot_dn_per_e: float = 0.04
    blur_px: float = 0.8
    vignetting: float = 0.3
    background: float = 0.35
    clutter: bool = False
    colour: bool = False
    white_balance: tuple[float, float, float] = (0.92, 1.0, 0.88)

    def __post_init__(self) -> None:
        for k in (
            "gain",
            "offset_dn",
            "read_noise_dn",
            "shot_dn_per_e",
            "blur_px",
            "vignetting",
            "background",
        ):
            v = float(getattr(self, k))
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"Photometry.{k} must be a finite number >= 0, got {getattr(self, k)!r}")
            object.__setattr__(self, k, v)
        if self.vignetting > 1 or self.background > 1:
            raise ValueError("Photometry.vignetting and .background must be in [0, 1]")
        wb = tuple(float(x) for x in self.white_balance)
        if len(wb) != 3 or not all(np.isfinite(x) and x > 0 for x in wb):
            raise ValueError(
                f"white_balance must be three positive gains (B, G, R), got {self.white_balance!r}"
            )
        object.__setattr__(self, "white_balance", wb)

    @classmethod
    def noise_free(cls, **kw) -> Photometry:
        """No read or shot noise and no vignetting (the optics blur stays): only 8-bit rounding.

        Keyword arguments override fields, e.g. ``Photometry.noise_free(blur_px=0.0)``.
        """
        base = {"read_noise_dn": 0.0, "shot_dn_per_e": 0.0, "vignetting": 0.0}
        base.update(kw)
        return cls(**base)


_VIGNETTES: OrderedDict = OrderedDict()


def _cos4(camera: CameraModel) -> np.ndarray:
    key = camera.key
    v = _VIGNETTES.get(key)
    if v is None:
        w, h = camera.image_size
        x = ((np.arange(w, dtype=np.float32) - camera.cx) / camera.fx)[None, :]
        y = ((np.arange(h, dtype=np.float32) - camera.cy) / camera.fy)[:, None]
        v = (1.0 / (1.0 + x * x + y * y)) ** 2
        v = v.astype(np.float32)
        v.setflags(write=False)
        _VIGNETTES[key] = v
        while len(_VIGNETTES) > 4:
            _VIGNETTES.popitem(last=False)
    return v


#: Supersampling of the targets' regions for the optics blur (see :func:`blurred_reflectance`).
BLUR_SUPERSAMPLE = 2


def _supersampled_camera(camera: CameraModel, ss: int) -> CameraModel:
    """The same camera with ``ss`` x ``ss`` pixels per pixel: pixel u spans sub-pixels ss*u .. ss*u+ss-1."""
    w, h = camera.image_size
    return CameraModel(
        (w * ss, h * ss),
        camera.fx * ss,
        camera.fy * ss,
        camera.cx * ss + (ss - 1) / 2,
        camera.cy * ss + (ss - 1) / 2,
        camera.dist,
        model=camera.model,
    )


def blurred_reflectance(
    camera: CameraModel,
    targets,
    *,
    background=0.35,
    blur_px: float,
    supersample: int = BLUR_SUPERSAMPLE,
) -> np.ndarray:
    """Scene reflectance through the optics: a Gaussian PSF, then integration over each pixel.

    What a pixel records is the scene convolved with the lens's point-spread
    function and integrated over the pixel's area (box). Blurring the exact
    box-filtered image with a Gaussian kernel sampled at whole pixels is not the
    same near sharp edges: the error depends on where an edge falls within its
    pixel, and with board edges nearly parallel to the pixel grid it moved
    estimated board depths by tens of micrometres from image to image. Here the
    targets' regions are rendered at ``supersample`` x ``supersample`` sub-pixels
    (exact area coverage), blurred there (the kernel is then well sampled), and
    averaged back to pixels; the smooth background keeps the one-pixel blur.
    At 2x the board depths are within about 2 um of a 4x rendering.

    Parameters
    ----------
    camera : CameraModel
    targets : sequence of Target
    background : float or ndarray, shape (h, w)
    blur_px : float
        PSF sigma, px (0: no blur, the box-filtered image).
    supersample : int
        Sub-pixels per pixel and axis in the targets' regions (1: sampled kernel only).

    Returns
    -------
    ndarray, shape (h, w), float32
    """
    targets = list(targets)
    ss = int(supersample)
    if blur_px <= 0 or ss <= 1:
        refl = render_reflectance(camera, targets, background=background).astype(np.float32)
        if blur_px <= 0:
            return refl
        return cv2.GaussianBlur(refl, (0, 0), blur_px, borderType=cv2.BORDER_REPLICATE)
    # The targets are drawn only at the fine resolution below; the background alone at 1x.
    w, h = camera.image_size
    if np.isscalar(background):
        out = np.full((h, w), float(background), dtype=np.float32)
    else:
        out = cv2.GaussianBlur(
            np.asarray(background, dtype=np.float32), (0, 0), blur_px, borderType=cv2.BORDER_REPLICATE
        )
    for tg in targets:
        patch = target_patch(camera, targets, tg, background=background, blur_px=blur_px, supersample=ss)
        if patch is not None:
            (i0, i1, j0, j1), values = patch
            out[i0:i1, j0:j1] = values
    return out


def blur_reach_px(blur_px: float) -> int:
    """How far the optics blur reaches around a target, px: beyond 4 sigma the PSF is negligible."""
    return int(np.ceil(4 * blur_px)) + 2


def patch_bounds(
    camera: CameraModel, target, blur_px: float
) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]] | None:
    """Where :func:`target_patch` renders a target and which part of it it keeps.

    Returns
    -------
    ((R0, R1, C0, C1), (i0, i1, j0, j1)) or None
        Rows and columns (end excluded) of the image rendered at the fine resolution (the
        target's bounding box widened by twice the blur's reach ``m``, :func:`blur_reach_px`),
        and of the patch kept (widened by ``m``: the blur there saw no border); None when the
        target is out of the image.
    """
    w, h = camera.image_size
    m = blur_reach_px(blur_px)
    bb = target_bbox(camera, target.texture(), target.board2cam, (0, 0, w, h))
    if bb is None:
        return None
    r0, r1, c0, c1 = bb
    render_box = (max(r0 - 2 * m, 0), min(r1 + 2 * m, h), max(c0 - 2 * m, 0), min(c1 + 2 * m, w))
    keep = (max(r0 - m, 0), min(r1 + m, h), max(c0 - m, 0), min(c1 + m, w))
    return render_box, keep


def target_patch(
    camera: CameraModel,
    targets,
    target,
    *,
    background=0.35,
    blur_px: float,
    supersample: int = BLUR_SUPERSAMPLE,
    rays=None,
    tile_px: int = 0,
    chunk_rows: int = 128,
) -> tuple[tuple[int, int, int, int], np.ndarray] | None:
    """The blurred reflectance around one target, as :func:`blurred_reflectance` pastes it.

    The part of the image :func:`patch_bounds` gives is rendered at ``supersample`` x
    ``supersample`` sub-pixels with every target of ``targets`` that falls in it, blurred,
    and averaged back to pixels.

    Parameters
    ----------
    camera : CameraModel
    targets : sequence of Target
        Every target of the scene (those near ``target`` are drawn in its patch too).
    target : Target
    background : float or ndarray, shape (h, w)
    blur_px : float
        PSF sigma, px (> 0).
    supersample : int
        > 1.
    rays : optional
        The supersampled camera's rays (see :func:`stiffmap.sim.reflectance.render_reflectance`).
    tile_px : int
        Tiles of uniform pixels (see :func:`stiffmap.sim.reflectance.render_reflectance`).
    chunk_rows : int
        Fine rows rendered at a time (memory; the values do not depend on it).

    Returns
    -------
    ((i0, i1, j0, j1), values) or None
        Rows i0..i1-1 and columns j0..j1-1 of the image, and their values, float32 (None: the
        target is out of the image).
    """
    bounds = patch_bounds(camera, target, blur_px)
    if bounds is None:
        return None
    (R0, R1, C0, C1), (i0, i1, j0, j1) = bounds
    ss = int(supersample)
    if np.isscalar(background):
        bg = float(background)
    else:
        bg = np.repeat(np.repeat(np.asarray(background)[R0:R1, C0:C1], ss, axis=0), ss, axis=1)
    cam_s = _supersampled_camera(camera, ss)
    fine = render_reflectance(
        cam_s,
        targets,
        background=bg,
        roi=(C0 * ss, R0 * ss, C1 * ss, R1 * ss),
        rays=rays,
        tile_px=tile_px,
        chunk_rows=chunk_rows,
    )
    fine = cv2.GaussianBlur(fine.astype(np.float32), (0, 0), blur_px * ss, borderType=cv2.BORDER_REPLICATE)
    if ss == 2:
        # The mean of each 2 x 2 block, summed as NumPy's mean sums them (the same float32
        # values, bit for bit), without its 15 times slower strided reduction.
        coarse = ((fine[0::2, 0::2] + fine[0::2, 1::2]) + (fine[1::2, 0::2] + fine[1::2, 1::2])) / np.float32(
            4
        )
    else:
        coarse = fine.reshape(R1 - R0, ss, C1 - C0, ss).mean(axis=(1, 3))
    return (i0, i1, j0, j1), coarse[i0 - R0 : i1 - R0, j0 - C0 : j1 - C0]


def apply_photometry(
    reflectance: np.ndarray,
    camera: CameraModel,
    photometry: Photometry,
    rng: np.random.Generator | None = None,
    *,
    blurred: bool = False,
) -> np.ndarray:
    """8-bit image from a full-frame reflectance image (see :class:`Photometry`).

    Parameters
    ----------
    reflectance : ndarray, shape (h, w)
        As from :func:`render_reflectance` over the whole image.
    camera : CameraModel
    photometry : Photometry
    rng : numpy Generator, optional
        The noise source (seeded by the caller); needed when the photometry has noise.
    blurred : bool
        The reflectance already went through the optics (:func:`blurred_reflectance`);
        otherwise it is blurred here with a sampled Gaussian kernel, which is exact
        only for smooth images.

    Returns
    -------
    ndarray of uint8, shape (h, w) or (h, w, 3)
    """
    w, h = camera.image_size
    img = np.asarray(reflectance, dtype=np.float32)
    if img.shape != (h, w):
        raise ValueError(f"reflectance must have shape ({h}, {w}), got {img.shape}")
    ph = photometry
    if ph.blur_px > 0 and not blurred:
        img = cv2.GaussianBlur(img, (0, 0), ph.blur_px, borderType=cv2.BORDER_REPLICATE)
    sig = sensor_signal(img, camera, ph)
    if has_noise(ph):
        if rng is None:
            raise ValueError("apply_photometry needs a random generator (rng) when the photometry has noise")
        sd = noise_sigma(sig, ph)
        sig = sig + sd * rng.standard_normal(sig.shape, dtype=np.float32)
    sig += np.float32(ph.offset_dn)
    raw = np.clip(np.rint(sig), 0, 255).astype(np.uint8)
    if ph.colour:
        return cv2.cvtColor(raw, cv2.COLOR_BayerBG2BGR_EA)
    return raw


def has_noise(photometry: Photometry) -> bool:
    """The photometry draws noise (read or shot noise)."""
    return photometry.read_noise_dn > 0 or photometry.shot_dn_per_e > 0


def sensor_signal(
    reflectance: np.ndarray, camera: CameraModel, photometry: Photometry, origin: tuple[int, int] = (0, 0)
) -> np.ndarray:
    """Mean signal above the black level, DN (float32), of a blurred reflectance image or of a part.

    Illumination gain, vignetting and, for a colour camera, the Bayer filter's gains (R at even
    rows and columns of the whole image).

    Parameters
    ----------
    reflectance : ndarray, shape (n, m), float32
        The image's rows ``origin[0]`` .. ``origin[0] + n - 1`` and columns ``origin[1]`` ...
    camera : CameraModel
    photometry : Photometry
    origin : (int, int)
        Row and column of ``reflectance[0, 0]`` in the image.

    Returns
    -------
    ndarray, shape (n, m), float32, DN
    """
    ph = photometry
    r0, c0 = (int(v) for v in origin)
    n, m = reflectance.shape
    sig = reflectance * np.float32(255.0 * ph.gain)
    if ph.vignetting > 0:
        sig *= (
            np.float32(1.0 - ph.vignetting)
            + np.float32(ph.vignetting) * _cos4(camera)[r0 : r0 + n, c0 : c0 + m]
        )
    if ph.colour:
        # A Bayer sensor: one colour filter per pixel, R at even rows and columns.
        b, g, r = (np.float32(x) for x in ph.white_balance)
        er, ec = r0 % 2, c0 % 2  # the first even row and column of the part
        sig[er::2, ec::2] *= r
        sig[er::2, 1 - ec :: 2] *= g
        sig[1 - er :: 2, ec::2] *= g
        sig[1 - er :: 2, 1 - ec :: 2] *= b
    return sig


def noise_sigma(signal: np.ndarray, photometry: Photometry) -> np.ndarray:
    """1 sigma of the sensor noise, DN (float32), at each pixel's mean signal (read and shot noise).

    Parameters
    ----------
    signal : ndarray, float32, DN
        Mean signal above the black level (:func:`sensor_signal`).
    photometry : Photometry

    Returns
    -------
    ndarray, the shape of ``signal``, float32, DN
    """
    ph = photometry
    return np.sqrt(np.float32(ph.read_noise_dn**2) + np.float32(ph.shot_dn_per_e) * signal)
