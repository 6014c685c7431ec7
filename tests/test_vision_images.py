"""Reading images: formats, bit depths, and a clear error naming the file for every bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.shared_data import CALIB_DIR

from stiffmap.errors import InputError
from stiffmap.vision import ImageError, check_image_size, read_image
from stiffmap.vision.images import check_image

CALIB = CALIB_DIR


@pytest.fixture
def grey(rng) -> np.ndarray:
    return rng.integers(0, 256, size=(48, 64), dtype=np.uint8)


@pytest.mark.parametrize("ext", [".png", ".tif", ".bmp", ".pgm", ".webp"])
def test_lossless_formats_round_trip(tmp_path, grey, ext):
    p = tmp_path / f"img{ext}"
    params = [cv2.IMWRITE_WEBP_QUALITY, 101] if ext == ".webp" else []
    assert cv2.imwrite(str(p), grey, params)
    out = read_image(p)
    assert out.dtype == np.uint8 and out.shape == (48, 64)
    np.testing.assert_array_equal(out, grey)


def test_real_tiff_reads_as_8bit_grey():
    img = read_image(CALIB / "Image1.tif")
    assert img.shape == (480, 640) and img.dtype == np.uint8
    assert 0 < img.mean() < 255


def test_colour_jpeg_becomes_grey(tmp_path, rng):
    bgr = np.zeros((40, 60, 3), np.uint8)
    bgr[:, :30] = (255, 255, 255)
    p = tmp_path / "c.jpg"
    cv2.imwrite(str(p), bgr, [cv2.IMWRITE_JPEG_QUALITY, 100])
    out = read_image(p)
    assert out.shape == (40, 60)
    assert out[:, :25].mean() > 250 and out[:, 35:].mean() < 5  # grey levels


def test_one_image_check_for_the_vision_functions():
    grey = np.zeros((20, 30), np.uint8)
    assert check_image(grey) is not None and check_image(grey).shape == (20, 30)
    bgr = np.zeros((20, 30, 3), np.uint8)
    bgr[..., 2] = 255  # red
    out = check_image(bgr)
    assert out.shape == (20, 30) and out.dtype == np.uint8 and out.max() == 76  # grey of red
    wide = np.zeros((20, 30), np.uint16)
    assert check_image(wide, uint16=True).dtype == np.uint16
    assert check_image(grey[:, ::2]).flags.c_contiguous
    for bad in (wide, grey.astype(np.float32), np.zeros((5, 30), np.uint8), np.zeros((20, 30, 4), np.uint8)):
        with pytest.raises(ValueError, match="2-D grey"):
            check_image(bad)


def test_16bit_is_scaled_by_its_maximum(tmp_path):
    img = np.zeros((20, 30), np.uint16)
    img[:, 15:] = 4095  # a 12-bit sensor in a 16-bit file
    img[0, 0] = 2048
    p = tmp_path / "d.png"
    cv2.imwrite(str(p), img)
    out = read_image(p)
    assert out.dtype == np.uint8
    assert out[5, 20] == 255 and out[5, 5] == 0 and out[0, 0] == 128


@pytest.mark.parametrize("ext", [".png", ".tif", ".bmp", ".jpg", ".pgm"])
@pytest.mark.parametrize("keep", [0.3, 0.95])
def test_truncated_file_is_a_clear_error(tmp_path, grey, ext, keep):
    full = tmp_path / f"full{ext}"
    cv2.imwrite(str(full), np.kron(grey, np.ones((4, 4), np.uint8)))
    data = full.read_bytes()
    bad = tmp_path / f"cut{ext}"
    bad.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(ImageError) as e:
        read_image(bad)
    msg = str(e.value)
    assert str(bad) in msg
    assert "truncated" in msg


def test_not_an_image(tmp_path):
    p = tmp_path / "notes.png"
    p.write_text("these are not pixels\n")
    with pytest.raises(ImageError, match=r"notes\.png: not an image file"):
        read_image(p)


def test_empty_missing_and_directory(tmp_path):
    empty = tmp_path / "empty.tif"
    empty.write_bytes(b"")
    with pytest.raises(ImageError, match=r"empty\.tif: empty file"):
        read_image(empty)
    with pytest.raises(ImageError, match=r"nope\.png: no such file or folder"):
        read_image(tmp_path / "nope.png")
    with pytest.raises(ImageError, match="is a directory"):
        read_image(tmp_path)


def test_image_error_is_an_input_error():
    assert issubclass(ImageError, InputError)


def test_size_check_names_file_and_both_sizes():
    img = np.zeros((480, 640), np.uint8)
    check_image_size(img, (640, 480), source="a.png")
    with pytest.raises(InputError) as e:
        check_image_size(img, (2592, 1944), source="a.png", camera_source="cam.json")
    msg = str(e.value)
    assert msg.startswith("a.png:") and "640x480" in msg and "2592x1944" in msg and "cam.json" in msg
