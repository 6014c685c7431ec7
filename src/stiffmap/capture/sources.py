"""Camera sources for a guided capture: one small protocol, several cameras behind it.

A source is opened, gives frames (an image and its timestamp) one after the other, and is
closed; it is a context manager. Every source here follows :class:`CameraSource`:

- :class:`OpenCVSource`: OpenCV's ``VideoCapture`` -- a device index (``0``), a stream URL
  (``rtsp://...``, ``http://...``) or a video file (``run.mp4``);
- :class:`FolderSource`: the image files of a folder, played back in name order (a camera
  vendor's program that writes every frame to disk, or a recorded session);
- :class:`GenICamSource`: industrial cameras through ``harvesters`` and a GenTL producer
  (``.cti``), an optional extra: ``pip install 'stiffmap[genicam]'``;
- the simulated camera of the virtual test-bed, :class:`stiffmap.sim.live_camera.SimulatedCamera`
  (it follows the protocol without importing it: the test-bed sits below this layer).

Frames are 8-bit grey ``(h, w)`` or BGR ``(h, w, 3)`` arrays; timestamps are seconds on the
source's own clock (a device's: :func:`time.monotonic`; a file's: its position; the simulated
camera's: its simulated time), used only for differences. A source that cannot be opened, and
a video or folder that ends, raise :class:`~stiffmap.errors.InputError` naming the source.
"""

from __future__ import annotations

import abc
import importlib
import os
import time
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Protocol, Self, runtime_checkable

import cv2
import numpy as np

from ..errors import InputError, Stop
from ..vision.images import read_image

__all__ = [
    "Frame",
    "FrameLike",
    "CameraSource",
    "SourceEnded",
    "OpenCVSource",
    "FolderSource",
    "GenICamSource",
    "IMAGE_SUFFIXES",
    "GENICAM_EXTRA",
]

#: Image files a :class:`FolderSource` plays back.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm")
#: How to install the GenICam support.
GENICAM_EXTRA = "pip install 'stiffmap[genicam]'"


class SourceEnded(Stop):
    """The source has no more frames (a video file or a folder came to its end, a camera stopped):
    a :class:`~stiffmap.errors.Stop`."""


@runtime_checkable
class FrameLike(Protocol):
    """What :meth:`CameraSource.grab` returns: an image and when it was taken."""

    image: np.ndarray
    timestamp_s: float
    index: int


@dataclass(frozen=True)
class Frame:
    """One frame of a camera.

    Attributes
    ----------
    image : ndarray, shape (h, w) or (h, w, 3), uint8
        Grey, or BGR (OpenCV's order).
    timestamp_s : float
        When it was taken, s, on the source's clock (only differences mean something).
    index : int
        0-based count of the frames grabbed since the source was opened.
    """

    image: np.ndarray
    timestamp_s: float
    index: int


@runtime_checkable
class CameraSource(Protocol):
    """A camera: open it, grab frames, close it (or use it in a ``with`` block).

    Attributes
    ----------
    name : str
        What the source is, for messages (``"camera 0"``, ``"video run.mp4"``).
    image_size : (int, int)
        (width, height), px; known once the source is open.
    """

    name: str

    @property
    def image_size(self) -> tuple[int, int]: ...

    def open(self) -> None: ...

    def grab(self) -> FrameLike: ...

    def close(self) -> None: ...

    def __enter__(self) -> Self: ...

    def __exit__(self, exc_type, exc: BaseException | None, tb: TracebackType | None) -> None: ...


class _Source(abc.ABC):
    """Context-manager plumbing shared by the sources (each opens and closes its camera)."""

    name = "camera"

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    @abc.abstractmethod
    def open(self) -> None:
        """Open the camera (InputError when it cannot be)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the camera (safe to call twice)."""


def _grey_or_bgr(img: np.ndarray, name: str) -> np.ndarray:
    """An 8-bit grey or BGR frame from what a camera gave (16-bit scaled down, BGRA without alpha)."""
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[:, :, :3]
    if a.dtype == np.uint16:
        a = (a >> 8).astype(np.uint8) if a.max() > 255 else a.astype(np.uint8)
    if a.dtype != np.uint8 or a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        raise InputError(f"gave a frame of {a.dtype} {a.shape}; expected 8-bit grey or colour", source=name)
    return np.ascontiguousarray(a)


class OpenCVSource(_Source):
    """A camera, stream or video file through OpenCV's ``VideoCapture``.

    Parameters
    ----------
    target : int or str
        A device index (``0``), a stream URL, or a video file.
    """

    def __init__(self, target: int | str) -> None:
        self.target = target
        self.is_file = isinstance(target, str) and "://" not in target
        self.name = (
            f"camera {target}"
            if isinstance(target, int)
            else (f"video {target}" if self.is_file else f"stream {target}")
        )
        self._cap: cv2.VideoCapture | None = None
        self._size = (0, 0)
        self._count = 0

    @property
    def image_size(self) -> tuple[int, int]:
        return self._size

    def open(self) -> None:
        if self.is_file:
            p = Path(str(self.target))
            if not p.is_file():
                raise InputError("no such video file", source=str(p))
        log = cv2.utils.logging
        level = log.getLogLevel()
        log.setLogLevel(log.LOG_LEVEL_SILENT)  # the backends' warnings: the message below says it
        try:
            cap = cv2.VideoCapture(self.target)
        finally:
            log.setLogLevel(level)
        if not cap.isOpened():
            cap.release()
            what = (
                "cannot be opened as a video (not a video file, or a codec this OpenCV build lacks)"
                if self.is_file
                else "cannot be opened (not connected, busy in another program, or no permission)"
            )
            raise InputError(what, source=self.name)
        self._cap = cap
        self._size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        self._count = 0

    def grab(self) -> Frame:
        if self._cap is None:
            raise InputError("is not open", source=self.name)
        ok, img = self._cap.read()
        if not ok or img is None:
            if self.is_file:
                raise SourceEnded(f"the video ended after {self._count} frames", source=self.name)
            raise SourceEnded(f"stopped giving frames after {self._count}", source=self.name)
        if self.is_file:
            t = float(self._cap.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
        else:
            t = time.monotonic()
        frame = Frame(_grey_or_bgr(img, self.name), t, self._count)
        self._size = (frame.image.shape[1], frame.image.shape[0])
        self._count += 1
        return frame

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class FolderSource(_Source):
    """The image files of a folder, played back in name order at a set frame rate.

    Parameters
    ----------
    folder : path
    fps : float
        Frames per second the timestamps assume (the files carry no time).
    """

    def __init__(self, folder: str | os.PathLike, fps: float = 10.0) -> None:
        self.folder = Path(folder)
        self.name = f"folder {self.folder}"
        if not (np.isfinite(fps) and fps > 0):
            raise InputError(f"frame rate must be a positive number of frames per second, got {fps!r}")
        self.fps = float(fps)
        self._files: list[Path] = []
        self._next = 0
        self._size = (0, 0)

    @property
    def image_size(self) -> tuple[int, int]:
        return self._size

    def open(self) -> None:
        if not self.folder.is_dir():
            raise InputError("no such folder", source=str(self.folder))
        files = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
        if not files:
            raise InputError(f"holds no image files ({', '.join(IMAGE_SUFFIXES)})", source=str(self.folder))
        self._files = files
        self._next = 0
        first = read_image(files[0])
        self._size = (first.shape[1], first.shape[0])

    def grab(self) -> Frame:
        if self._next >= len(self._files):
            raise SourceEnded(f"no more images after {len(self._files)}", source=str(self.folder))
        k = self._next
        self._next += 1
        return Frame(read_image(self._files[k]), k / self.fps, k)

    def close(self) -> None:
        self._files = []


class GenICamSource(_Source):
    """An industrial (GenICam) camera through ``harvesters`` and a GenTL producer.

    Parameters
    ----------
    producer : path
        The camera vendor's GenTL producer (a ``.cti`` file).
    serial : str, optional
        The camera's serial number (default: the first camera found).

    Needs the optional extra: ``pip install 'stiffmap[genicam]'``.
    """

    def __init__(self, producer: str | os.PathLike, serial: str | None = None) -> None:
        self.producer = Path(producer)
        self.serial = serial or None
        self.name = f"GenICam camera {serial or '(first)'} through {self.producer.name}"
        self._h = None
        self._ia = None
        self._count = 0
        self._size = (0, 0)

    @property
    def image_size(self) -> tuple[int, int]:
        return self._size

    def open(self) -> None:
        try:
            # Optional extra, loaded only when a GenICam camera is asked for.
            core = importlib.import_module("harvesters.core")
        except ImportError:
            raise InputError(
                f"GenICam cameras need the 'harvesters' package: {GENICAM_EXTRA}", source=self.name
            ) from None
        if not self.producer.is_file():
            raise InputError("no such GenTL producer (.cti) file", source=str(self.producer))
        h = core.Harvester()
        try:
            h.add_file(str(self.producer))
            h.update()
            infos = list(h.device_info_list)
            if not infos:
                raise InputError("the GenTL producer finds no camera", source=self.name)
            ia = h.create({"serial_number": self.serial} if self.serial else 0)
            ia.start()
        except InputError:
            h.reset()
            raise
        except Exception as e:  # harvesters raises its own and GenTL errors
            h.reset()
            raise InputError(f"cannot be opened: {type(e).__name__}: {e}", source=self.name) from None
        self._h, self._ia, self._count = h, ia, 0

    def grab(self) -> Frame:
        if self._ia is None:
            raise InputError("is not open", source=self.name)
        try:
            with self._ia.fetch(timeout=5.0) as buf:
                c = buf.payload.components[0]
                img = np.array(c.data, copy=True).reshape(c.height, c.width, -1)
        except Exception as e:
            raise SourceEnded(f"stopped giving frames: {type(e).__name__}: {e}", source=self.name) from None
        frame = Frame(_grey_or_bgr(img, self.name), time.monotonic(), self._count)
        self._size = (frame.image.shape[1], frame.image.shape[0])
        self._count += 1
        return frame

    def close(self) -> None:
        if self._ia is not None:
            self._ia.stop()
            self._ia.destroy()
            self._ia = None
        if self._h is not None:
            self._h.reset()
            self._h = None
