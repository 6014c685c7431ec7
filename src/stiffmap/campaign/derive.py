"""Deriving one robot position's results from its image poses: displacements, repeat statistics, K.

:func:`derive_position` follows the steps of ``docs/campaigns.md`` ("Derive"):

1. ``cam2base`` from the fixed target in all of the position's images (mean
   pose, the reference paper's eq. 1): the camera does not move during a
   campaign, and each image's own fixed-target pose would add that target's
   noise, magnified by the lever arm between the two targets, to every
   displacement;
2. with ``pairing = "mean-reference"``, the mean unloaded pose of the position;
3. the compliant displacement of ``point_mm`` for every load case and repeat,
   in the base frame, with its covariance;
4. repeat statistics per load case;
5. K with standard errors, indices, flags and ISO 5725 repeatability.

The camera calibration's error is common to every image of the campaign: each displacement
carries its sensitivity G to the camera's parameters (from the poses' sensitivities, as
:func:`stiffmap.vision.displacement.compliant_displacement` does) and, with the camera's
covariance Sigma_c, its share G Sigma_c G^T of the displacement's covariance
(``cov_calibration``); K's covariance gets the share of that common error through the
identification (``identify_stiffness(common_jacobian=..., common_cov=...)``), not as
independent noise.

The results are rows of the results database (dicts of column values), ready
for :meth:`stiffmap.campaign.store.Store.save_position`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import __version__
from ..errors import InputError, StiffmapWarning
from ..geometry import cam2base_from_fixed, displacement_from_poses, mean_transform
from ..identify import identify_stiffness
from ..loads import LoadCase
from ..stats import describe, precision
from ..vision.displacement import base_frame_calibration_jacobian, pair_calibration_jacobian
from .measure import ImageRow
from .positions import Pair, PositionTask
from .spec import CampaignSpec, TargetsSpec
from .store import to_json

__all__ = ["PositionResult", "derive_position"]


@dataclass
class PositionResult:
    """Derived rows of one position, ready to be written."""

    displacements: list[dict] = field(default_factory=list)
    repeat_stats: list[dict] = field(default_factory=list)
    stiffness: dict = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _BaseFrame:
    """How a position's camera-frame poses are put in the robot base frame."""

    cam2base: np.ndarray  # (4, 4); the identity when the campaign has no fixed target
    name: str  # "base", or "cam" without a fixed target
    missing: bool  # a fixed target is expected but was found in no image
    # Mean sensitivity (3, n) of the fixed target's rotation to the camera's parameters (None:
    # not in the base frame, or unknown in some image).
    fixed_rotation_jacobian: np.ndarray | None = None

    @property
    def rotation6(self) -> np.ndarray:
        """The (6, 6) block rotation turning a (translation, rotation) covariance into the base frame."""
        R = self.cam2base[:3, :3]
        B = np.zeros((6, 6))
        B[:3, :3] = R
        B[3:, 3:] = R
        return B


def derive_position(
    task: PositionTask,
    rows: dict[str, ImageRow],
    loads: list[LoadCase],
    spec: CampaignSpec,
    method: str,
    inputs_hash: str,
    phash: str,
    *,
    calibration_cov: np.ndarray | None = None,
) -> PositionResult:
    """Displacements (base frame), repeat statistics and K of one position.

    Parameters
    ----------
    task : PositionTask
    rows : dict of str to ImageRow
        The measured images of the position, by relative path.
    loads : list of LoadCase
        The campaign's load cases (N, base frame).
    spec : CampaignSpec
    method : str
        Identification method (:func:`stiffmap.identify.identify_stiffness`).
    inputs_hash, phash : str
        Stored with the rows: the hash of the position's inputs and of the parameters.
    calibration_cov : ndarray, shape (n, n), optional
        The camera's calibration covariance (``CameraModel.calibration_cov``); None: unknown,
        the calibration's share is left out (and said nowhere to be included).
    """
    res = PositionResult()
    base = _base_frame(task, rows, spec.targets, res.problems)
    mean_ref = spec.images.pairing == "mean-reference"
    reference = _mean_reference(task, rows, res.problems) if mean_ref else None
    point = np.asarray(spec.targets.mobile.point_mm, dtype=float)
    F_cols, D_cols, G_cols = [], [], []
    per_load: dict[int, list[np.ndarray]] = {}
    for pr in task.pairs:
        row, d, G = _pair_displacement(
            task, pr, rows, base, mean_ref, reference, point, phash, calibration_cov
        )
        res.displacements.append(row)
        if d is not None:
            F_cols.append(loads[pr.load - 1].force)
            D_cols.append(d[:3])
            G_cols.append(G)
            per_load.setdefault(pr.load, []).append(d)
    res.repeat_stats = _repeat_stats(task.index, per_load)
    common = None
    if calibration_cov is not None and G_cols and all(G is not None for G in G_cols):
        common = (np.asarray([G[:3] for G in G_cols]), np.asarray(calibration_cov))
    res.stiffness, problem = _stiffness(
        task, F_cols, D_cols, per_load, method, mean_ref, inputs_hash, phash, common
    )
    if problem is not None:
        res.problems.append(problem)
    return res


def _base_frame(
    task: PositionTask, rows: dict[str, ImageRow], targets: TargetsSpec, problems: list[str]
) -> _BaseFrame:
    """``cam2base`` from the fixed target's mean pose over the position's images (paper eq. 1)."""
    fixed_ok = [r for r in rows.values() if r.ok and r.fixed2cam is not None]
    if targets.fixed is None:
        return _BaseFrame(np.eye(4), "cam", missing=False)
    if not fixed_ok:
        problems.append(f"position {task.index}: the fixed target was not found in any image")
        return _BaseFrame(np.eye(4), "cam", missing=True)
    cam2base = cam2base_from_fixed(targets.fixed.fixed2base, mean_transform([r.fixed2cam for r in fixed_ok]))
    jac = [r.fixed_cal_jac for r in fixed_ok]
    Af = None if any(a is None for a in jac) else np.mean([a[3:] for a in jac], axis=0)
    return _BaseFrame(cam2base, "base", missing=False, fixed_rotation_jacobian=Af)


def _mean_reference(
    task: PositionTask, rows: dict[str, ImageRow], problems: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """The mean unloaded pose of the position (camera frame), its covariance and calibration
    sensitivity (the mean of its images'; None when unknown in one), or None."""
    refs = [
        rows[rel] for rel in dict.fromkeys(pr.unloaded for pr in task.pairs) if rel in rows and rows[rel].ok
    ]
    if not refs:
        problems.append(f"position {task.index}: no usable unloaded image")
        return None
    jac = [r.mobile_cal_jac for r in refs]
    A = None if any(a is None for a in jac) else np.mean(jac, axis=0)
    return mean_transform([r.mobile2cam for r in refs]), sum(r.mobile_cov for r in refs) / len(refs) ** 2, A


def _pair_displacement(
    task: PositionTask,
    pr: Pair,
    rows: dict[str, ImageRow],
    base: _BaseFrame,
    mean_ref: bool,
    reference: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None,
    point: np.ndarray,
    phash: str,
    calibration_cov: np.ndarray | None,
) -> tuple[dict[str, Any], np.ndarray | None, np.ndarray | None]:
    """The ``displacements`` row of one pair, its displacement (6,) when it could be measured,
    and the displacement's sensitivity (6, n) to the camera's parameters (None: unknown)."""
    u, lo = rows.get(pr.unloaded), rows.get(pr.loaded)
    row = {
        "position": task.index,
        "load": pr.load,
        "repeat": pr.repeat,
        "unloaded": "(mean of the position's unloaded images)" if mean_ref else pr.unloaded,
        "loaded": pr.loaded,
        "frame": base.name,
        "params_hash": phash,
        "version": __version__,
    }
    bad = []
    for rel, r in ((pr.loaded, lo),) if mean_ref else ((pr.unloaded, u), (pr.loaded, lo)):
        if rel in task.missing:
            bad.append(f"missing image {rel}")
        elif r is None or not r.ok:
            bad.append(f"{rel}: {r.error if r is not None else 'not measured'}")
    if mean_ref and reference is None:
        bad.append("no usable unloaded image")
    if bad or base.missing:
        # Without the fixed target the displacement cannot be put in the base frame.
        row.update(status="failed", error="; ".join(bad) or "the fixed target was not found in any image")
        return row, None, None
    M0, cov0, A0 = reference if mean_ref else (u.mobile2cam, u.mobile_cov, u.mobile_cal_jac)
    d = displacement_from_poses(base.cam2base @ M0, base.cam2base @ lo.mobile2cam, point)
    cov = _displacement_covariance(M0, cov0, lo.mobile_cov, point, base.rotation6)
    G = _calibration_jacobian(M0, A0, lo, point, d, base)
    cov_cal = None
    if G is not None and calibration_cov is not None:
        cov_cal = G @ calibration_cov @ G.T
        cov_cal = 0.5 * (cov_cal + cov_cal.T)
        cov = cov + cov_cal
    row.update(status="ok", error=None, d=to_json(d), cov=to_json(cov), cov_calibration=to_json(cov_cal))
    return row, d, G


def _calibration_jacobian(
    M0: np.ndarray, A0: np.ndarray | None, lo: ImageRow, point: np.ndarray, d: np.ndarray, base: _BaseFrame
) -> np.ndarray | None:
    """d(displacement, base frame) / d(camera parameters), (6, n); None when a sensitivity is unknown."""
    if A0 is None or lo.mobile_cal_jac is None:
        return None
    G = pair_calibration_jacobian(M0, A0, lo.mobile2cam, lo.mobile_cal_jac, point)
    if base.name != "base":
        return G
    if base.fixed_rotation_jacobian is None:
        return None
    return base_frame_calibration_jacobian(G, d, base.cam2base[:3, :3], base.fixed_rotation_jacobian)


def _displacement_covariance(
    M0: np.ndarray, cov0: np.ndarray, cov1: np.ndarray, point: np.ndarray, B: np.ndarray
) -> np.ndarray:
    """Covariance (6, 6) of the displacement of ``point`` between two poses, in the base frame."""
    # (t, left r) pose noise moves the point R p + t by dt + dr x (R p).
    v = M0[:3, :3] @ point
    J = np.eye(6)
    J[:3, 3:] = -np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return B @ J @ (cov0 + cov1) @ J.T @ B.T


def _repeat_stats(position: int, per_load: dict[int, list[np.ndarray]]) -> list[dict[str, Any]]:
    """Repeat statistics per load case: components and norm of the translation, rotations."""
    out = []
    for ld, ds in sorted(per_load.items()):
        arr = np.asarray(ds)
        quantities = {
            "dx": arr[:, 0],
            "dy": arr[:, 1],
            "dz": arr[:, 2],
            "norm": np.linalg.norm(arr[:, :3], axis=1),
        }
        quantities.update({"rx": arr[:, 3], "ry": arr[:, 4], "rz": arr[:, 5]})
        for q, vals in quantities.items():
            c = describe(vals)
            out.append(
                {"position": position, "load": ld, "quantity": q, "mean": c.mean, "std": c.std, "n": c.n}
            )
    return out


def _stiffness(
    task: PositionTask,
    F_cols: list[np.ndarray],
    D_cols: list[np.ndarray],
    per_load: dict[int, list[np.ndarray]],
    method: str,
    mean_ref: bool,
    inputs_hash: str,
    phash: str,
    common: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[dict[str, Any], str | None]:
    """The ``stiffness`` row of a position from its usable (force, displacement) pairs, and its problem.

    ``common``: the displacements' sensitivities (n, 3, p) to the camera's parameters and
    the camera's covariance (p, p), whose share K's covariance then includes.
    """
    x, y, z = task.xyz
    st = {
        "position": task.index,
        "x": x,
        "y": y,
        "z": z,
        "method": method,
        "inputs_hash": inputs_hash,
        "params_hash": phash,
        "version": __version__,
        "n_obs": len(F_cols),
    }
    if len(F_cols) < 3:
        st.update(
            status="failed", error=f"only {len(F_cols)} usable load measurement(s); at least 3 are needed"
        )
        return st, f"position {task.index}: {st['error']}"
    F = np.asarray(F_cols).T
    D = np.asarray(D_cols).T
    try:
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always", StiffmapWarning)
            # Against a mean reference every displacement shares its error: estimate that offset.
            fit = identify_stiffness(
                F,
                D,
                method=method,
                offset=mean_ref,
                common_jacobian=None if common is None else common[0],
                common_cov=None if common is None else common[1],
            )
    except (InputError, ValueError) as e:
        st.update(status="failed", error=str(e))
        return st, f"position {task.index}: {e}"
    idx = fit.indices
    prec = _precision(per_load)
    st.update(
        status="ok",
        error=None,
        K=to_json(fit.K),
        K_std=to_json(fit.K_std),
        K_cov=to_json(fit.K_cov),
        K_cov_calibration=to_json(fit.K_cov_common),
        det=idx.det,
        eigenvalues=to_json(idx.eigenvalues),
        min_principal=idx.min_principal,
        K_condition=idx.condition,
        design_condition=fit.condition,
        rank=fit.rank,
        dof=fit.dof,
        residual_rms=to_json(fit.residual_rms),
        flags=to_json(list(fit.flags) + prec.pop("flags")),
        precision=to_json(prec),
    )
    return st, None


def _precision(per_load: dict[int, list[np.ndarray]]) -> dict[str, Any]:
    """Repeatability of the displacement components over the load cases (ISO 5725-2).

    The load cases are the conditions and the repeats the replicates; each
    component's deviations from its load case's mean are analysed, so s_r is
    the pooled repeatability. A flag is raised only when Cochran's C finds the
    largest within-load-case variance an outlier (1 %): that test already
    accounts for the number of load cases, whereas Mandel's k, tested load case
    by load case, would raise a false alarm at about one position in four (27
    tests at 1 % per position); its values are kept as information.
    """
    groups = {k: np.asarray(v) for k, v in per_load.items() if len(v) >= 2}
    out: dict[str, Any] = {"flags": []}
    if len(groups) < 2:
        return out
    labels = [f"load {k}" for k in groups]
    for j, name in enumerate(("dx", "dy", "dz")):
        res = precision([g[:, j] - g[:, j].mean() for g in groups.values()], labels)
        out[name] = {"s_r": res.s_r, "r": res.r, "mandel_k": res.k.tolist(), "cochran_C": res.cochran_C}
        out["flags"].extend(f"{name} repeatability outlier ({o})" for o in res.outliers if "Cochran" in o)
    return out
