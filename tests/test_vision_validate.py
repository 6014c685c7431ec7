"""Stage validation: known displacements along an axis, statistics per step, plot."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from helpers.board_scenes import exact_board_pose

from stiffmap.camera import reference_camera
from stiffmap.errors import InputError
from stiffmap.geometry import matrix_from_rotvec
from stiffmap.report.validation import stage_plot_svg
from stiffmap.targets import Chessboard
from stiffmap.vision import ImageMeasurement, validate_stage
from stiffmap.vision.file_commands import validate_files
from stiffmap.vision.validate import REFERENCE_TABLE_I


def _m(name, T):
    return ImageMeasurement(image=name, mobile=exact_board_pose(T, np.eye(6) * 1e-8, 48))


def test_steps_statistics_and_axis(rng):
    T0 = np.eye(4)
    T0[:3, :3] = matrix_from_rotvec([0.2, -0.4, 0.1])
    T0[:3, 3] = [10.0, -5.0, 700.0]
    axis = np.array([0.6, 0.0, 0.8])
    ref = [_m(f"r{k}", T0) for k in range(3)]
    moved, truth = [], {}
    for nom in (2.0, 5.0, 10.0, 20.0):
        vals = []
        for k in range(10):
            T = T0.copy()
            noise = rng.normal(scale=0.003, size=3)
            T[:3, 3] = T0[:3, 3] + nom * axis + noise
            moved.append((nom, _m(f"s{nom}_{k}", T)))
            vals.append(np.linalg.norm(nom * axis + noise))
        truth[nom] = np.array(vals)
    moved.append((5.0, ImageMeasurement(image="bad.png", error="bad.png: truncated PNG file")))
    res = validate_stage(ref, moved)
    np.testing.assert_allclose(np.abs(res.axis @ axis), 1.0, atol=1e-4)
    assert res.axis @ axis > 0  # signed along growing nominal displacements
    assert [s.nominal_mm for s in res.steps] == [2.0, 5.0, 10.0, 20.0]
    for s in res.steps:
        assert s.n == 10
        assert s.mean_mm == pytest.approx(truth[s.nominal_mm].mean(), abs=1e-12)
        assert s.std_mm == pytest.approx(truth[s.nominal_mm].std(ddof=1), abs=1e-12)
        assert abs(s.error_mm) < 0.004 and s.std_mm < 0.006  # mm
        assert abs(s.along_mean_mm - s.nominal_mm) < 0.004
    assert res.failed == (("bad.png", "bad.png: truncated PNG file"),)
    assert res.rms_error_mm < 0.006
    svg = stage_plot_svg(res)
    root = ET.fromstring(svg)
    assert len(root.findall(".//{http://www.w3.org/2000/svg}circle")) == 8  # 4 steps x 2 panels
    # The reference study's Table I, for the side-by-side print.
    assert REFERENCE_TABLE_I[2.0] == (1.99, 0.28)


def test_no_usable_reference_or_moved_image():
    bad = ImageMeasurement(image="r.png", error="r.png: no 8x6 chessboard found in the image")
    good = _m("m.png", np.eye(4) + np.diag([0, 0, 0, 0]))
    with pytest.raises(InputError, match="no usable reference image") as e:
        validate_stage([bad], [(2.0, good)])
    # the image named once: its error names it already ('r.png: r.png: no 8x6 ...' before)
    expected = "no usable reference image (nominal 0): r.png: no 8x6 chessboard found in the image"
    assert str(e.value) == expected
    with pytest.raises(InputError, match="no usable image of a moved stage"):
        validate_stage([good], [(2.0, bad)])
    with pytest.raises(ValueError, match="nominal"):
        validate_stage([good], [(-1.0, good)])


def test_a_manifest_without_a_usable_reference_names_each_image_once_with_its_line(tmp_path):
    """It said 'ref.png: ref.png: ... (line 2: ref.png: ...)': each reason twice, the image three times."""
    (tmp_path / "stage.csv").write_text("image,nominal_mm\nref.png,0\nm.png,2\n")
    with pytest.raises(InputError) as e:
        validate_files(tmp_path / "stage.csv", reference_camera(), Chessboard(8, 6, 10.0))
    msg = str(e.value)
    assert msg.startswith(f"{tmp_path / 'stage.csv'}: no usable reference image (nominal 0): line 2: "), msg
    assert msg.count("ref.png") == 1 and "no such file" in msg, msg
