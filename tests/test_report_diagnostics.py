"""The report's diagnostics (issue 26 item 5): the error chart's axis, position ticks, linearity
and residuals of d = C F, compliance ellipsoids, calibration coverage, the set-up summary and
the embedded image, each checked against an independent computation."""

from __future__ import annotations

import base64
import warnings

import cv2
import numpy as np
import pytest
from helpers.random_matrices import random_spd

from stiffmap.identify import identify_stiffness
from stiffmap.loads import forces_matrix, paper9
from stiffmap.report.data import BoardImage, LoadData, MeasuredStiffness, ReportData, SetupItem
from stiffmap.report.example import example_vision
from stiffmap.report.figure_data import (
    calibration_corners,
    compliance_ellipsoids,
    displacement_residuals,
    error_axis,
    load_directions,
    position_dtick,
)
from stiffmap.report.png import grey_png, reduce_image


@pytest.fixture(scope="module")
def small():
    """The example campaign at 8 positions (two planes), 3 repeats: every optional part filled."""
    return example_vision(seed=2, per_side=2, planes=(-200.0, -310.0), repeats=3)


# ------------------------------------------------------------------ the relative error chart
def test_the_relative_error_axis_starts_at_zero_and_is_linear_in_both_back_ends(small) -> None:
    from stiffmap.report.interactive_figures import truth_figure
    from stiffmap.report.static_figures import truth_figure as static_truth

    err = 100 * small.truth_error
    fig = truth_figure(small)
    ax = fig.layout.yaxis2
    assert ax.type == "linear" and ax.range[0] == 0.0
    assert not [t for t in fig.data if t.type == "bar"]  # dots, not bars from a baseline
    # Every finite error is drawn: inside the axis, or at its top saying its value.
    drawn = [t for t in fig.data if t.xaxis == "x2"]
    inside = np.concatenate([t.y for t in drawn if t.mode == "markers"])
    assert np.all((inside >= 0) & (inside <= ax.range[1]))
    beyond = [t for t in drawn if t.mode == "markers+text"]
    n_beyond = sum(len(t.x) for t in beyond)
    assert len(inside) + n_beyond == np.isfinite(err).sum()
    mfig = static_truth(small)
    a2 = mfig.axes[1]
    assert a2.get_yscale() == "linear" and a2.get_ylim()[0] == 0.0
    # Positions are counted: ticks on whole numbers only, in both back-ends.
    ticks = [t for t in a2.get_xticks() if a2.get_xlim()[0] <= t <= a2.get_xlim()[1]]
    assert ticks and all(float(t).is_integer() for t in ticks)
    xa = fig.layout.xaxis2
    assert xa.tickmode == "linear" and xa.tick0 == 1 and float(xa.dtick).is_integer()


def test_error_axis_puts_an_outlier_at_the_top_and_keeps_zero() -> None:
    v = np.array([0.3, 0.5, 0.2, 0.4, np.nan, 0.35, 0.45, 0.25, 0.3, 0.4, 88.8])
    top, above = error_axis(v)
    # The 90th percentile of the ten finite values is 0.5 + 0.1 (88.8 - 0.5) = 9.33 (numpy's
    # linear rule): 88.8 > 4 x 9.33; the axis is fitted to the other nine.
    assert above.tolist() == [False] * 10 + [True]
    assert top == pytest.approx(1.15 * 0.5)
    top, above = error_axis(np.array([0.3, 0.5, 0.2]))
    assert not above.any() and top == pytest.approx(1.15 * 0.5)
    assert error_axis(np.array([np.nan]))[0] == 1.0


@pytest.mark.parametrize(("n", "step"), [(1, 1), (12, 1), (24, 1), (25, 2), (48, 2), (200, 9)])
def test_position_ticks_are_whole_numbers_and_at_most_24(n: int, step: int) -> None:
    assert position_dtick(n) == step and n / step <= 24


# ------------------------------------------------------------------ linearity, residuals of d = C F
@pytest.mark.parametrize("offset", [False, True])
def test_residuals_of_d_equal_CF_satisfy_the_fit_normal_equations(offset: bool, rng) -> None:
    """With K identified from the same displacements (least squares, the default method), what
    d - C F (- b) leaves is orthogonal to every force component (and, with the offset, sums to
    zero): the normal equations of that fit, written here independently of the report."""
    F = forces_matrix(paper9())  # (3, 9), N
    L, R = F.shape[1], 4
    K_true = np.stack([random_spd(rng) * 10 for _ in range(2)])
    b = np.array([0.02, -0.01, 0.015]) if offset else np.zeros(3)
    vectors = np.empty((2, L, R, 3))
    K = np.empty((2, 3, 3))
    for i in range(2):
        D = np.linalg.solve(K_true[i], F)[:, :, None] + b[:, None, None] + rng.normal(0, 0.003, (3, L, R))
        vectors[i] = np.moveaxis(D, 0, -1)
        FF = np.repeat(F[:, :, None], R, axis=2).reshape(3, -1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            K[i] = identify_stiffness(FF, D.reshape(3, -1), offset=offset).K
    K[1] = np.nan  # a failed position: no residuals
    r = displacement_residuals(K, F.T, vectors, offset=offset)
    assert r.shape == vectors.shape and np.all(np.isnan(r[1]))
    flat = r[0].reshape(-1, 3)  # (L R, 3)
    Fr = np.repeat(F.T[:, None, :], R, axis=1).reshape(-1, 3)
    scale = np.abs(flat).max() * np.abs(Fr).max() * len(flat)
    assert np.abs(Fr.T @ flat).max() < 1e-9 * scale
    if offset:
        assert np.abs(flat.sum(axis=0)).max() < 1e-9 * np.abs(flat).max() * len(flat)
    # The noise is 3 um: what K leaves is of that size, not of the displacements' (mm).
    assert 1e-3 < np.sqrt(np.mean(flat**2)) < 6e-3


def test_load_directions_group_paper9_by_direction_with_increasing_force() -> None:
    groups = load_directions(forces_matrix(paper9()).T)
    assert [g.label for g in groups] == ["+y", "-x", "-z"]
    # 0.1, 0.2, 0.5 kg at g = 9.81 (the study's Table II), the load cases 7, 4, 1 along +y.
    for k, g in enumerate(groups):
        assert g.loads.tolist() == [6 + k, 3 + k, k]
        assert g.magnitude == pytest.approx([0.981, 1.962, 4.905])


def test_load_data_refuses_vectors_whose_norms_are_not_the_norms_given(rng) -> None:
    v = rng.normal(size=(2, 3, 2, 3))
    with pytest.raises(ValueError, match="vectors: their norms"):
        LoadData(("a", "b", "c"), rng.normal(size=(3, 3)), np.linalg.norm(v, axis=3) * 1.01, vectors=v)


# ------------------------------------------------------------------ principal directions
def test_compliance_ellipsoids_have_the_principal_compliances_as_semi_axes(rng) -> None:
    n = 4
    pos = np.array([[0, 0, -200], [100, 0, -200], [0, 100, -200], [0, 0, -300]], float)
    K = np.stack([random_spd(rng) * 5 for _ in range(n)])
    K[3] = np.diag([2.0, -1.0, 3.0])  # not positive definite: no ellipsoid, a cross instead
    data = ReportData(campaign=_info(), measured=MeasuredStiffness.from_K(pos, K))
    el = compliance_ellipsoids(data)
    assert el.index.tolist() == [0, 1, 2] and el.skipped.tolist() == [3]
    # The softest direction anywhere fills 0.45 of the smallest spacing (100 mm).
    assert el.semi_axes().max() == pytest.approx(45.0)
    V, faces, owner = el.triangles()
    for k, i in enumerate(el.index):
        w, U = np.linalg.eigh(0.5 * (K[i] + K[i].T))
        assert el.stiffness[k] == pytest.approx(w)
        # Every vertex on the ellipsoid x^T (U diag(k/scale)^2 U^T) x = 1 about the position.
        A = U @ np.diag((w / el.scale) ** 2) @ U.T
        x = V[owner == k] - pos[i]
        assert np.einsum("ij,jk,ik->i", x, A, x) == pytest.approx(1.0, abs=1e-9)
    assert faces.max() < len(V) and faces.min() >= 0


def _info():
    from stiffmap.report.data import CampaignInfo

    return CampaignInfo("t", "vision")


# ------------------------------------------------------------------ calibration coverage
def test_coverage_counts_every_used_corner_in_its_cell(small) -> None:
    cc = calibration_corners(small)
    views = small.calibration.camera["views"]
    used = [v for v in views if v["used"] and "corners_px" in v]
    assert len(cc.corners) == sum(len(v["corners_px"]) for v in used) == 15 * 54
    counts, xe, ye = cc.coverage(cells=16)
    assert counts.sum() == len(cc.corners)
    # One cell counted by hand.
    r, c = np.unravel_index(np.argmax(counts), counts.shape)
    x, y = cc.corners[:, 0], cc.corners[:, 1]
    mine = np.sum((x >= xe[c]) & (x < xe[c + 1]) & (y >= ye[r]) & (y < ye[r + 1]))
    assert counts[r, c] == mine
    assert np.allclose(cc.residuals, np.concatenate([v["residuals_px"] for v in used]))


# ------------------------------------------------------------------ the embedded image
def test_grey_png_decodes_to_the_same_pixels_and_reduction_averages_blocks(rng) -> None:
    a = rng.integers(0, 256, size=(37, 53), dtype=np.uint8)
    back = cv2.imdecode(np.frombuffer(grey_png(a), np.uint8), cv2.IMREAD_UNCHANGED)
    assert back.dtype == np.uint8 and np.array_equal(back, a)
    big = rng.integers(0, 256, size=(31, 2000), dtype=np.uint8)
    small, k = reduce_image(big, max_width=960)
    assert k == 3 and small.shape == (10, 666)  # ceil(2000 / 960); partial blocks left out
    assert small[4, 100] == round(big[12:15, 300:303].mean())
    assert reduce_image(a)[1] == 1


def test_board_image_checks_its_png_and_size() -> None:
    png = base64.b64encode(grey_png(np.zeros((10, 20), np.uint8))).decode()
    ok = dict(name="i.png", png_base64=png, image_size=np.array([60.0, 30.0]), scale=3.0)
    corners = dict(corners_px=np.zeros((2, 2)), corner_board=("mobile 9x6", "mobile 9x6"))
    assert BoardImage(**ok, **corners).png[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="not a 640x30 image"):
        BoardImage(**{**ok, "image_size": np.array([640.0, 30.0])}, **corners)
    with pytest.raises(ValueError, match="not a PNG"):
        BoardImage(**{**ok, "png_base64": base64.b64encode(b"GIF89a" + bytes(40)).decode()}, **corners)


def test_new_parts_survive_the_json_round_trip(small, tmp_path) -> None:
    png = base64.b64encode(grey_png(np.full((4, 6), 7, np.uint8))).decode()
    bi = BoardImage("i.png", png, np.array([6.0, 4.0]), 1.0, np.array([[1.0, 2.0]]), ("mobile 9x6",))
    data = ReportData(**{**_fields(small), "board_image": bi})
    back = ReportData.from_dict(data.to_dict())
    assert back.setup == small.setup and all(isinstance(s, SetupItem) for s in back.setup)
    assert np.array_equal(back.loads.vectors, small.loads.vectors, equal_nan=True)
    assert np.array_equal(back.loads.residuals, small.loads.residuals, equal_nan=True)
    assert back.board_image.png == bi.png and back.board_image.corner_board == ("mobile 9x6",)
    cams = back.calibration.camera["views"]
    assert cams[0]["corners_px"] == small.calibration.camera["views"][0]["corners_px"]


def _fields(d: ReportData) -> dict:
    return {k: getattr(d, k) for k in d.__dataclass_fields__}


def test_view_names_drop_the_folder_the_views_share() -> None:
    from stiffmap.report.figure_data import view_names

    views = [{"image": "/data/lab/calib/v01.png"}, {"image": "/data/lab/calib/sub/v02.png"}, {}]
    assert view_names(views[:2]) == ["v01.png", "sub/v02.png"]
    assert view_names(views) == ["/data/lab/calib/v01.png", "/data/lab/calib/sub/v02.png", "view 3"]
    assert view_names([{"image": "/data/x.png"}]) == ["/data/x.png"]  # one view: its name as given
