"""Stiffness identification from applied loads and measured displacements.

Model: each load case i applies a force (or wrench) f_i and the robot moves by
d_i = C f_i + e_i, where C = K^-1 is the compliance and e_i the measurement
error of the displacement. Three estimators are offered:

``compliance`` (default)
    Least squares of displacements on forces, D = C F (weighted when
    displacement covariances are given), then K = C^-1. Forces are known far
    better than displacements (calibrated masses versus image or sensor
    measurements), so the errors are in D and this regression is unbiased in C.
    Regressing forces on noisy displacements instead (the ``paper`` estimator)
    is the errors-in-variables situation: noise in the regressor inflates
    D D^T by about n Sigma and shrinks K toward zero (regression dilution,
    attenuation bias), by a relative amount of order n sigma^2 / |D|^2.

``paper``
    The reference vision study's estimator (its eq. 10): K = F D^T (D D^T)^-1.
    Kept for comparison with published results.

``spd``
    The compliance model constrained to a symmetric positive-definite C
    (hence K): a physically admissible stiffness (Maxwell-Betti reciprocity
    and stability). Solved as symmetric least squares, and through a Cholesky
    parameterisation when the unconstrained symmetric solution is not
    positive definite.

Uncertainty: the covariance of vec(C) is (F W F^T)^-1-type from the given
displacement covariances, or (F F^T)^-1 kron Sigma with Sigma estimated from the
residuals (multivariate regression, n - m degrees of freedom); it is carried to
K by the first-order rule dK = -K dC K. Confidence intervals use Student's t
with Welch-Satterthwaite effective degrees of freedom when Sigma is estimated.

Common error: displacements measured with one instrument share its calibration's error (a
camera whose focal length is off by 1e-3 makes every displacement 1e-3 too large). That error
is not noise: it does not average out over load cases, the residuals do not show it (a scale
error is absorbed by C) and it is not independent between load cases. Given each
displacement's sensitivity G_i = d d_i / d c to the common parameters c and their covariance
Sigma_c (``common_jacobian``, ``common_cov``), its share of K's covariance is
(dK/dc) Sigma_c (dK/dc)^T, with dK/dc exact through the estimator (linear in D for the
compliance estimators at fixed weights); it is added to the noise's share and kept apart
(``K_cov_common``). The effective degrees of freedom then follow Welch-Satterthwaite with
the common share taken as known.

Shapes: m = 3 (forces, N, and translations, mm: K in N/mm) or m = 6 (wrenches
N, N*mm and displacements mm, rad). Load cases are columns: F and D are m x n.
Covariances of K are over ``K.ravel()`` (row-major).
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .errors import DesignError, IllConditionedWarning
from .stats import chi2_sf, hotelling_t2_sf, t_ppf
from .stiffness import (
    DISPLACEMENT_FLOOR_MM,
    StiffnessIndices,
    check_stiffness_matrix,
    compliance_from_stiffness,
    directional_stiffness,
    stiffness_from_compliance,
    stiffness_indices,
)

__all__ = [
    "METHODS",
    "StiffnessFit",
    "StiffnessIndices",
    "identify_stiffness",
    "stiffness_indices",
    "physical_flags",
    "asymmetry_p_value",
    "asymmetry_dof",
    "flipped_axes",
    "directional_stiffness",
    "compliance_from_stiffness",
    "stiffness_from_compliance",
]

Method = Literal["compliance", "paper", "spd"]
METHODS: tuple[str, ...] = ("compliance", "paper", "spd")

#: Above this condition number of the normalised load design a warning is issued.
CONDITION_WARN = 1e3
#: Smallest compliance eigenvalue of the ``spd`` fit, relative to the largest.
SPD_EIGEN_FLOOR = 1e-6
#: Relative asymmetry flagged when no covariance is available to test it.
ASYMMETRY_FLAG = 0.1
#: The level of the asymmetry test of one K (a campaign controls it over its positions:
#: :mod:`stiffmap.campaign.flags`).
ASYMMETRY_P = 0.01


def _asymmetry_map(m: int) -> np.ndarray:
    """The linear map from K.ravel() (row-major) to the upper-triangle entries of K - K^T."""
    iu = np.triu_indices(m, 1)
    A = np.zeros((iu[0].size, m * m))
    for k, (i, j) in enumerate(zip(*iu, strict=True)):
        A[k, i * m + j] = 1.0
        A[k, j * m + i] = -1.0
    return A


def asymmetry_dof(K, K_cov, dof: float, K_cov_common=None) -> float:
    """The effective degrees of freedom of K - K^T's covariance when the displacements'
    covariance Sigma was estimated from ``dof`` residual degrees of freedom.

    ``K_cov`` (less the known ``K_cov_common``) is J (Sigma_hat kron P) J^T with J = dK/dC
    and Sigma_hat ~ Wishart(Sigma, dof) / dof (module docstring, "Uncertainty"). The q x q
    covariance V_hat = A K_cov A^T of the q upper-triangle entries of K - K^T is linear in
    Sigma_hat but not itself a Wishart matrix; it is taken as Wishart(V, nu) / nu with nu
    matching E |V^-1/2 V_hat V^-1/2 - I|_F^2 = q (q + 1) / nu (a matrix Satterthwaite: for
    q = 1, Satterthwaite's nu = 2 V^2 / Var V_hat). Writing Sigma = R R^T, P = L L^T and
    U_k = V^-1/2 A J (r_k kron L) for the columns r_k of R, that expectation is
    (sum_kl tr((U_l^T U_k)^2) + |sum_k U_k^T U_k|_F^2) / dof. nu >= dof in every case
    measured (benchmarks/results/asymmetry.md); it grows with the known share.

    Raises
    ------
    numpy.linalg.LinAlgError
        When the covariance of K - K^T is singular (below 1e-12 of its largest eigenvalue).
    """
    K = np.asarray(K, dtype=np.float64)
    m = K.shape[0]
    A = _asymmetry_map(m)
    q = A.shape[0]
    J = _inverse_jacobian(K)
    V = A @ np.asarray(K_cov, dtype=np.float64) @ A.T
    scale = float(np.abs(V).max())  # nu is unchanged by scaling K_cov: keep the numbers near 1
    noise = np.asarray(K_cov, dtype=np.float64) / scale
    if K_cov_common is not None:
        noise = noise - np.asarray(K_cov_common, dtype=np.float64) / scale
    C = np.linalg.inv(K)
    Jinv = -np.kron(C, C.T)  # the inverse of J
    blocks = (Jinv @ noise @ Jinv.T).reshape(m, m, m, m).transpose(0, 2, 1, 3)  # [i, j] = Sigma_ij P
    sigma = np.einsum("ijkk->ij", blocks)
    # Whitened through V's correlation matrix (6x6 mixes N/mm and N mm/rad entries): T^T T = V^-1.
    sd = np.sqrt(np.clip(np.diag(V / scale), 0.0, None))
    if not sd.min() > 0:
        raise np.linalg.LinAlgError("the covariance of K - K^T is singular")
    w, E = np.linalg.eigh(V / scale / np.outer(sd, sd))
    if not w.min() > 1e-12 * w.max():
        raise np.linalg.LinAlgError("the covariance of K - K^T is singular")
    if not np.trace(sigma) > 0:  # nothing estimated (noise-free data): the covariance is known
        return float("inf")
    P = np.einsum("iikl->kl", blocks) / np.trace(sigma)  # Sigma kron P up to a scale that cancels
    R, L = _psd_root(sigma), _psd_root(P)
    G = (E / np.sqrt(w)) @ E.T @ (A @ J / sd[:, None])  # T A J: M_kl's traces are those of V^-1/2
    U = np.stack([G @ np.kron(R[:, [k]], L) for k in range(m)])  # (m, q, m)
    Z = np.einsum("lqa,kqb->lkab", U, U)  # U_l^T U_k
    total = np.einsum("lkab,lkba->", Z, Z) + float(np.sum(np.einsum("kqa,kqb->ab", U, U) ** 2))
    return float(dof * q * (q + 1) / total) if total > 0 else float("inf")


def _psd_root(S: np.ndarray) -> np.ndarray:
    """R with R R^T = S for a symmetric positive semi-definite S (rounding's negatives clipped)."""
    w, V = np.linalg.eigh(0.5 * (S + S.T))
    return V * np.sqrt(np.clip(w, 0.0, None))


def asymmetry_p_value(K, K_cov, dof: float | None = None, K_cov_common=None) -> float:
    """The probability of an asymmetry K - K^T at least as large as K's if K were symmetric:
    the Wald statistic T^2 of K - K^T's q upper-triangle entries against their covariance
    from ``K_cov`` (over K's row-major entries), referred to Hotelling's law with the
    effective degrees of freedom of :func:`asymmetry_dof` when that covariance was
    estimated from ``dof`` residual degrees of freedom (the chi-square law of q, too eager
    then, when ``dof`` is None: a given, known covariance). ``K_cov_common``: the known share
    of ``K_cov`` (``StiffnessFit.K_cov_common``). 1 when K is symmetric; NaN (not tested:
    :func:`physical_flags` then applies ``ASYMMETRY_FLAG``) when ``K_cov`` has non-finite
    entries, when K - K^T's covariance is singular (too few independent residuals: 4 load
    cases of a 3x3 K, or the same load cases copied) or the effective dof is below q."""
    K = np.asarray(K, dtype=np.float64)
    K_cov = np.asarray(K_cov, dtype=np.float64)
    if not np.all(np.isfinite(K_cov)):
        return float("nan")
    A = _asymmetry_map(K.shape[0])
    a = A @ K.ravel()
    if not np.any(a):
        return 1.0
    try:
        t2 = float(a @ np.linalg.solve(A @ K_cov @ A.T, a))
        nu = np.inf if dof is None else asymmetry_dof(K, K_cov, dof, K_cov_common)
    except np.linalg.LinAlgError:  # no p-value: a sentinel 0 or 1 would read as a test's
        return float("nan")
    return hotelling_t2_sf(t2, a.size, nu)


def physical_flags(
    K,
    K_cov=None,
    *,
    dof: float | None = None,
    K_cov_common=None,
    asymmetry_threshold: float = ASYMMETRY_FLAG,
) -> tuple[str, ...]:
    """Physical admissibility checks of an identified stiffness.

    - ``asymmetric``: K differs from K^T more than its uncertainty allows (the test of
      :func:`asymmetry_p_value` at 1 % when ``K_cov`` is given: Hotelling's law when it was
      estimated from ``dof`` residual degrees of freedom, chi-square when ``dof`` is None),
      or by more than ``asymmetry_threshold`` relative otherwise (or when the test cannot be
      made: K - K^T's covariance singular, its effective degrees of freedom too few);
    - ``not positive definite``: the symmetric part has an eigenvalue <= 0
      (the robot would give way under some load);
    - ``det <= 0``: the reference paper published such matrices without comment.

    Returns
    -------
    tuple of str
        Human-readable flags; empty when K passes every check.
    """
    K = check_stiffness_matrix(K)
    idx = stiffness_indices(K)
    flags: list[str] = []
    p = float("nan")
    if K_cov is not None and np.all(np.isfinite(K_cov)):
        p = asymmetry_p_value(K, K_cov, dof, K_cov_common)
    if p < ASYMMETRY_P:
        flags.append(f"asymmetric: |K-K^T|/|K| = {idx.asymmetry:.3g}, beyond its uncertainty (p = {p:.2g})")
    elif np.isnan(p) and idx.asymmetry > asymmetry_threshold:
        flags.append(f"asymmetric: |K-K^T|/|K| = {idx.asymmetry:.3g} > {asymmetry_threshold:g}")
    S = 0.5 * (K + K.T)
    w = np.linalg.eigvalsh(S)
    if np.any(w <= 0):
        bad = ", ".join(f"{x:.4g}" for x in w[w <= 0])
        flags.append(f"not positive definite: symmetric part has eigenvalue(s) {bad}")
    if idx.det <= 0:
        flags.append(f"det <= 0: det(K) = {idx.det:.4g}")
    if np.any(w <= 0):
        flags.append(_sign_hint(K))
    return tuple(flags)


#: K's axes by its size, and their names as displacement and as load components.
AXES = {2: ("x", "y"), 3: ("x", "y", "z"), 6: ("x", "y", "z", "rx", "ry", "rz")}
_DISP_NAME = {"x": "dx", "y": "dy", "z": "dz", "rx": "rx", "ry": "ry", "rz": "rz"}
_LOAD_NAME = {"x": "fx", "y": "fy", "z": "fz", "rx": "mx", "ry": "my", "rz": "mz"}


def flipped_axes(K) -> tuple[tuple[int, ...], ...]:
    """The smallest sets of axes whose sign, reversed, would make ``K`` positive definite.

    A displacement recorded with the wrong sign along the axes of S = diag(+-1) turns the
    robot's K into K S (its columns negated: the diagonal terms of those axes negative,
    det(K) of the other sign when their number is odd); a load applied the wrong way, into
    S K. Both have symmetric parts congruent to each other, so the test cannot tell them
    apart: it names the axes, not which of the two was reversed.

    Parameters
    ----------
    K : array_like, shape (m, m), m in (2, 3, 6)
        Stiffness (N/mm for 3x3).

    Returns
    -------
    tuple of tuple of int
        Each set (axis indices, ascending) of the smallest size for which the symmetric
        part of K S is positive definite; ``()`` when K is positive definite already or
        when no set of axes makes it so.
    """
    K = check_stiffness_matrix(K)
    m = K.shape[0]

    def positive(signs: np.ndarray) -> bool:
        Ks = K * signs[None, :]
        return bool(np.all(np.linalg.eigvalsh(0.5 * (Ks + Ks.T)) > 0))

    if positive(np.ones(m)):
        return ()
    for size in range(1, m + 1):
        found = []
        for axes in itertools.combinations(range(m), size):
            signs = np.ones(m)
            signs[list(axes)] = -1.0
            if positive(signs):
                found.append(axes)
        if found:
            return tuple(found)
    return ()


def _sign_hint(K: np.ndarray) -> str:
    """The flag that names the axis (or axes) whose sign looks reversed, with the evidence."""
    names = AXES[K.shape[0]]
    negative = [f"K[{names[i]},{names[i]}] = {K[i, i]:.4g}" for i in range(K.shape[0]) if K[i, i] < 0]
    found = flipped_axes(K)
    diag = f"{', '.join(negative)} < 0" if negative else ""
    if not found:
        return f"axis sign: no reversal of axis signs makes K positive definite{f' ({diag})' if diag else ''}"

    def one(axes: tuple[int, ...]) -> str:
        ax = [names[i] for i in axes]
        disp = ", ".join(_DISP_NAME[a] for a in ax)
        load = ", ".join(_LOAD_NAME[a] for a in ax)
        return f"{'/'.join(ax)} {'axis' if len(ax) == 1 else 'axes'} ({disp} or {load} of the wrong sign)"

    if len(found) == 1 and len(found[0]) == K.shape[0]:
        return (
            f"axis sign: every axis looks reversed ({diag}): -K is positive definite; displacements "
            "taken unloaded minus loaded, or loads of the opposite sign?"
        )
    if len(found) == 1:
        return (
            f"axis sign: the {one(found[0])} {'looks' if len(found[0]) == 1 else 'look'} reversed"
            f"{f'; {diag}' if diag else ''}: with {'its sign' if len(found[0]) == 1 else 'their signs'} "
            "reversed K is positive definite; check it (a sensor or camera axis the other way, a "
            "mirror, a load applied backwards)"
        )
    return (
        f"axis sign: reversing any one of the {'; '.join(one(a) for a in found)} would make K "
        f"positive definite{f' ({diag})' if diag else ''}; check those axes' signs"
    )


@dataclass(frozen=True)
class StiffnessFit:
    """Result of :func:`identify_stiffness`.

    Attributes
    ----------
    K : ndarray, shape (m, m)
        Stiffness, N/mm (3x3) or mixed units (6x6), in the frame of the data.
    K_cov : ndarray, shape (m*m, m*m)
        Covariance of ``K.ravel()`` (row-major). NaN when it cannot be known
        (no residual degrees of freedom and no given covariance).
    K_std : ndarray, shape (m, m)
        Standard errors of K's entries.
    C : ndarray, shape (m, m)
        Compliance K^-1 (mm/N for 3x3).
    method : str
    rank : int
        Rank of the load design F.
    condition : float
        Condition number of the load design (F with rows scaled to unit norm).
    residuals : ndarray, shape (m, n)
        d_i - C f_i (- b) for every load case (mm; rad for rotations).
    residual_rms : ndarray, shape (m,)
        RMS residual per displacement component.
    dof : int
        Residual degrees of freedom per displacement component, n - m (n - m - 1 with an offset).
    sigma : ndarray, shape (m, m)
        Displacement error covariance used for the uncertainty: estimated from
        the residuals or the mean of the given covariances.
    dof_effective : ndarray, shape (m, m)
        Welch-Satterthwaite degrees of freedom of each entry's variance
        (``inf`` when the covariance was given).
    chi2_reduced : float or None
        Weighted residual sum of squares per degree of freedom when
        displacement covariances were given (about 1 when they are right).
    flags : tuple of str
        Design and physical warnings (see :func:`physical_flags`).
    offset : ndarray, shape (m,), or None
        The estimated common displacement offset b (mm; rad), when asked for.
    K_cov_common : ndarray, shape (m*m, m*m), or None
        The share of ``K_cov`` from the displacements' common error (``common_jacobian``,
        ``common_cov``; e.g. the camera calibration's), None when none was given.
    cov_dof : int or None
        The residual degrees of freedom the displacements' covariance (the noise share of
        ``K_cov``) was estimated from; None when it was given (``disp_cov``).
    """

    K: np.ndarray
    K_cov: np.ndarray
    K_std: np.ndarray
    C: np.ndarray
    method: str
    rank: int
    condition: float
    residuals: np.ndarray
    residual_rms: np.ndarray
    dof: int
    sigma: np.ndarray
    dof_effective: np.ndarray
    chi2_reduced: float | None
    flags: tuple[str, ...] = field(default_factory=tuple)
    offset: np.ndarray | None = None
    K_cov_common: np.ndarray | None = None
    cov_dof: int | None = None

    @property
    def indices(self) -> StiffnessIndices:
        return stiffness_indices(self.K)

    @property
    def asymmetry_p(self) -> float:
        """The asymmetry test's p-value (:func:`asymmetry_p_value` with this fit's law)."""
        return asymmetry_p_value(self.K, self.K_cov, self.cov_dof, self.K_cov_common)

    @property
    def common_share(self) -> np.ndarray:
        """Share of each entry's variance from the common error, shape (m, m), 0..1 (NaN: not given)."""
        m = self.K.shape[0]
        if self.K_cov_common is None:
            return np.full((m, m), np.nan)
        tot = np.diag(self.K_cov)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.where(tot > 0, np.diag(self.K_cov_common) / tot, 0.0)
        return share.reshape(m, m)

    def confidence_interval(self, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Two-sided confidence interval of every entry of K.

        Uses Student's t with each entry's effective degrees of freedom.

        Returns
        -------
        lower, upper : ndarray, shape (m, m)
        """
        if not 0 < level < 1:
            raise ValueError(f"level must be in (0, 1), got {level}")
        q = t_ppf(0.5 + level / 2, self.dof_effective)
        return self.K - q * self.K_std, self.K + q * self.K_std


def _as_design(F, D, force_name: str, disp_name: str) -> tuple[np.ndarray, np.ndarray]:
    F = np.asarray(F, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64)
    for a, name in ((F, force_name), (D, disp_name)):
        if a.ndim == 2 and a.shape[0] not in (3, 6) and a.shape[1] in (3, 6):
            # The files hold one row per load case; the arrays one column (docs/conventions.md).
            raise ValueError(
                f"{name} has shape {a.shape}: one row per load case, as in the CSV files? The "
                f"arrays take one column per load case, shape ({a.shape[1]}, n): pass {name}.T"
            )
        if a.ndim != 2 or a.shape[0] not in (3, 6):
            raise ValueError(
                f"{name} must have shape (3, n) or (6, n) (one column per load case), got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"{name} has a NaN or infinite value (component {bad[0]}, load case {bad[1]})")
    if F.shape != D.shape:
        raise ValueError(
            f"{force_name} is {F.shape[0]}x{F.shape[1]} but {disp_name} is {D.shape[0]}x{D.shape[1]}: "
            "they need the same components and one column per load case"
        )
    return F, D


def _design_rank(F: np.ndarray) -> tuple[int, float]:
    """Rank and condition number of a load design.

    Rows of the same unit are scaled together (forces by the norm of the force
    block, moments by that of the moment block), so the condition number does
    not depend on N versus N*mm but does see a direction that is barely loaded.
    """
    m = F.shape[0]
    Fn = F.copy()
    for blk in (slice(0, 3), slice(3, 6)) if m == 6 else (slice(0, m),):
        nb = np.linalg.norm(F[blk])
        if nb > 0:
            Fn[blk] = F[blk] / nb
    s = np.linalg.svd(Fn, compute_uv=False)
    if s[0] == 0:
        return 0, float("inf")
    rank = int(np.sum(s > s[0] * 1e-10))
    cond = float(s[0] / s[-1]) if rank == m else float("inf")
    return rank, cond


def _check_cov(cov, m: int, n: int, name: str, *, semidefinite: bool = False) -> np.ndarray | None:
    if cov is None:
        return None
    S = np.asarray(cov, dtype=np.float64)
    if S.shape == (m, n):  # standard deviations per component
        S = np.stack([np.diag(S[:, i] ** 2) for i in range(n)])
    if S.shape == (m, m):
        S = np.broadcast_to(S, (n, m, m)).copy()
    if S.shape != (n, m, m):
        raise ValueError(f"{name} must have shape ({n}, {m}, {m}), ({m}, {m}) or ({m}, {n}); got {S.shape}")
    if not np.all(np.isfinite(S)):
        raise ValueError(f"{name} contains NaN or infinite values")
    for i in range(n):
        w = np.linalg.eigvalsh(0.5 * (S[i] + S[i].T))
        scale = max(abs(w[-1]), np.finfo(float).tiny)
        if (w[0] < -1e-12 * scale) if semidefinite else (w[0] <= 0):
            kind = "semi-definite" if semidefinite else "definite"
            raise ValueError(f"{name} of load case {i} is not positive {kind} (eigenvalue {w[0]:.3g})")
    return S


def _check_common(G, S, m: int, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The common error's (Jacobian (n, m, p), covariance (p, p)), checked; None when not given."""
    if G is None and S is None:
        return None
    if G is None or S is None:
        raise ValueError("common_jacobian and common_cov go together: give both or neither")
    G = np.asarray(G, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    if G.ndim != 3 or G.shape[:2] != (n, m):
        raise ValueError(f"common_jacobian must have shape ({n}, {m}, p), got {G.shape}")
    p = G.shape[2]
    if S.shape != (p, p):
        raise ValueError(f"common_cov must have shape ({p}, {p}) to match common_jacobian, got {S.shape}")
    if not (np.all(np.isfinite(G)) and np.all(np.isfinite(S))):
        raise ValueError("common_jacobian and common_cov must be finite")
    S = 0.5 * (S + S.T)
    w = np.linalg.eigvalsh(S) if p else np.zeros(0)
    if p and w[0] < -1e-12 * max(abs(w[-1]), np.finfo(float).tiny):
        raise ValueError(f"common_cov is not positive semi-definite (eigenvalue {w[0]:.3g})")
    return G, S


def _gls_compliance(F: np.ndarray, D: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Generalised least squares of vec(C) for d_i = C f_i, weights W_i = Sigma_i^-1.

    Returns C and the covariance of C.ravel() (row-major) = N^-1.
    """
    q, n = F.shape
    m = D.shape[0]
    # Row-major vec: C.ravel() = c, C f = (I kron f^T) c; C is m x q (q = m, or m + 1 with an offset).
    N = np.zeros((m * q, m * q))
    b = np.zeros(m * q)
    eye = np.eye(m)
    for i in range(n):
        A = np.kron(eye, F[:, i][None, :])  # (m, m*m)
        N += A.T @ W[i] @ A
        b += A.T @ W[i] @ D[:, i]
    Ninv = np.linalg.inv(N)
    c = Ninv @ b
    return c.reshape(m, q), Ninv


def _inverse_jacobian(K: np.ndarray) -> np.ndarray:
    """Jacobian of K.ravel() with respect to C.ravel() for K = C^-1 (row-major).

    dK = -K dC K  =>  vec_r(dK) = -(K kron K^T) vec_r(dC).
    """
    return -np.kron(K, K.T)


def _satterthwaite(G_rows: np.ndarray, P: np.ndarray, Sigma: np.ndarray, nu: int) -> np.ndarray:
    """Effective dof of variances tr(M Sigma_hat), M = G P G^T, Sigma_hat ~ W(Sigma, nu)/nu."""
    out = np.empty(G_rows.shape[0])
    m = Sigma.shape[0]
    for k in range(G_rows.shape[0]):
        G = G_rows[k].reshape(m, m)  # row-major vec(C) -> C-shaped weights
        M = G @ P @ G.T
        A = M @ Sigma
        tr = np.trace(A)
        tr2 = np.trace(A @ A)
        out[k] = nu * tr * tr / tr2 if tr2 > 0 else np.inf
    return out


def _sym_basis(m: int) -> np.ndarray:
    """Map from the m(m+1)/2 upper-triangle entries of a symmetric matrix to its ravel()."""
    iu = np.triu_indices(m)
    B = np.zeros((m * m, iu[0].size))
    for k, (i, j) in enumerate(zip(*iu, strict=True)):
        B[i * m + j, k] = 1.0
        B[j * m + i, k] = 1.0
    return B


def _spd_compliance(
    F: np.ndarray, D: np.ndarray, W: np.ndarray, Sigma: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None, bool]:
    """Symmetric positive-definite C minimising sum (d_i - C f_i)^T W_i (d_i - C f_i).

    Returns C, the covariance of C.ravel() from the symmetric least-squares
    sandwich with displacement covariances ``Sigma`` (n, m, m) (None if not
    given), and whether the positive-definite constraint was active.
    """
    m, n = F.shape
    B = _sym_basis(m)
    eye = np.eye(m)
    A = [np.kron(eye, F[:, i][None, :]) @ B for i in range(n)]  # (m, p) each
    H = sum(A[i].T @ W[i] @ A[i] for i in range(n))
    g = sum(A[i].T @ W[i] @ D[:, i] for i in range(n))
    Hinv = np.linalg.inv(H)
    x = Hinv @ g
    cov = None
    if Sigma is not None:
        meat = sum(A[i].T @ W[i] @ Sigma[i] @ W[i] @ A[i] for i in range(n))
        cov = B @ (Hinv @ meat @ Hinv) @ B.T
    C = (B @ x).reshape(m, m)
    w, V = np.linalg.eigh(C)
    if w[0] > 0:
        return C, cov, False
    # Constrained: C = L L^T with L lower triangular and a log-parameterised diagonal,
    # started from the eigenvalue-clipped symmetric solution.
    floor = max(abs(w[-1]) * 1e-6, 1e-12)
    L0 = np.linalg.cholesky((V * np.maximum(w, floor)) @ V.T)
    il = np.tril_indices(m)
    diag = il[0] == il[1]
    Lw = [np.linalg.cholesky(W[i]) for i in range(n)]

    def unpack(theta: np.ndarray) -> np.ndarray:
        vals = theta.copy()
        vals[diag] = np.exp(theta[diag])
        L = np.zeros((m, m))
        L[il] = vals
        return L

    def resid(theta: np.ndarray) -> np.ndarray:
        L = unpack(theta)
        Cc = L @ L.T
        return np.concatenate([Lw[i].T @ (D[:, i] - Cc @ F[:, i]) for i in range(n)])

    theta0 = L0[il].copy()
    theta0[diag] = np.log(theta0[diag])
    from scipy import optimize  # on first use: 0.15 s that most commands never need

    sol = optimize.least_squares(resid, theta0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    L = unpack(sol.x)
    # The optimum may lie on the boundary of the cone (a compliance eigenvalue -> 0, an
    # infinitely stiff direction); keep K finite with a floor relative to the largest.
    w, V = np.linalg.eigh(L @ L.T)
    w = np.maximum(w, SPD_EIGEN_FLOOR * w[-1])
    return (V * w) @ V.T, cov, True


# Longer than ~80 lines for its documentation: the parameters, raises and a doctest example
# take ~90 lines; the body (~25 lines) is the checks and _estimate.
def identify_stiffness(
    F,
    D,
    *,
    method: Method = "compliance",
    disp_cov=None,
    force_cov=None,
    offset: bool = False,
    common_jacobian=None,
    common_cov=None,
    names: tuple[str, str] = ("forces", "displacements"),
) -> StiffnessFit:
    """Identify a stiffness matrix from load cases.

    Parameters
    ----------
    F : array_like, shape (m, n)
        Applied forces (N), or wrenches (N, N*mm) for m = 6; one column per
        load case (repeats are extra columns with the same force). The CSV files
        hold one row per load case (``identify_from_files`` reads them so); an
        array of rows, shape (n, m), is refused with the hint to pass ``F.T``, but a
        square one (exactly 3 load cases of a 3x3 K) cannot be told apart: it is read
        as columns (``docs/conventions.md``, "Loads and stiffness").
    D : array_like, shape (m, n)
        Measured displacements (mm; rad for rotations), same order.
    method : {"compliance", "paper", "spd"}
        See the module docstring. ``compliance`` is the default and the one to
        trust; ``paper`` is the reference study's eq. 10; ``spd`` constrains K to
        be symmetric positive definite.
    disp_cov : array_like, optional
        Displacement covariance per load case, shape (n, m, m), one (m, m)
        for all, or standard deviations of shape (m, n). When given, the fit is
        weighted and K's covariance is propagated from it; otherwise the
        covariance is estimated from the residuals.
    force_cov : array_like, optional
        Force covariance per load case (same shapes), e.g. from the friction
        correction. Used with ``disp_cov``: a force error e_f moves the
        prediction by C e_f, so the effective displacement covariance is
        Sigma_d + C Sigma_f C^T (iterated with the estimate of C).
    offset : bool
        Also estimate a displacement offset b common to all load cases,
        D = C F + b 1^T. Use it when every displacement was measured against the
        same reference (for instance the mean unloaded pose of a robot position):
        that reference's error is then common to all of them, and without the
        offset it would leak into C as a non-symmetric error that the residuals do
        not show. Costs one residual degree of freedom per component.
    common_jacobian : array_like, shape (n, m, p), optional
        Each displacement's sensitivity to p parameters whose error all displacements share
        (the camera calibration's: ``Displacement.calibration_jacobian``); with
        ``common_cov`` (p, p), their covariance. Their share of K's covariance is added to
        ``K_cov`` and kept in ``K_cov_common`` (module docstring, "Common error").
    common_cov : array_like, shape (p, p), optional
    names : (str, str)
        What to call F and D in error messages (file names from the CLI).

    Returns
    -------
    StiffnessFit

    Raises
    ------
    DesignError
        If the loads span fewer independent directions than there are
        components (the rank found and needed are in the message); if the
        displacements cannot give a finite stiffness: all zero or below
        :data:`DISPLACEMENT_FLOOR_MM`, spanning fewer directions than there are
        components, or in a ratio to the forces beyond floating-point range
        (named after ``names[1]``).
    ValueError
        On bad shapes, NaN, an unknown method.

    Warns
    -----
    IllConditionedWarning
        When the normalised load design has a condition number above 1e3.

    Examples
    --------
    Six load cases of 5 N along +-x, +-y, +-z, three times each, on a known K (N/mm);
    the displacements (mm) carry 0.1 um of noise:

    >>> import numpy as np
    >>> K = np.array([[60.0, 4.0, -2.0], [4.0, 45.0, 3.0], [-2.0, 3.0, 200.0]])
    >>> F = np.hstack([5 * np.eye(3), -5 * np.eye(3)] * 3)  # N, shape (3, 18)
    >>> D = np.linalg.solve(K, F) + np.random.default_rng(0).normal(0, 1e-4, F.shape)
    >>> fit = identify_stiffness(F, D)
    >>> fit.K.round().astype(int).tolist()
    [[60, 4, -2], [4, 45, 3], [-2, 3, 200]]
    >>> bool(np.all(np.abs(fit.K - K) < 4 * fit.K_std))  # within 4 sigma of the truth
    True
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    F, D = _as_design(F, D, *names)
    m, n = F.shape
    rank, cond, Fa, flags = _check_design(F, offset, names[0])
    Sd = _check_cov(disp_cov, m, n, "disp_cov")
    Sf = _check_cov(force_cov, m, n, "force_cov", semidefinite=True)
    common = _check_common(common_jacobian, common_cov, m, n)
    disp_source = names[1] if names[1] != "displacements" else None
    _check_displacements(D, m, disp_source)
    try:
        # Under/overflow of degenerate data (tiny or huge ratios) is an error here, not a
        # RuntimeWarning followed by a NaN result.
        with np.errstate(over="raise", divide="raise", invalid="raise"):
            return _estimate(
                F, D, Fa, Sd, Sf, common, method=method, offset=offset, rank=rank, cond=cond, flags=flags
            )
    except (np.linalg.LinAlgError, FloatingPointError):
        raise DesignError(_no_finite_stiffness(F, D), source=disp_source) from None


def _check_design(F: np.ndarray, offset: bool, name: str):
    """The load design's rank and condition, checked (full rank; with an offset, loads not all
    on one plane missing the origin), the loads augmented by a row of ones with an offset, and
    the flags (a badly conditioned design: also warned)."""
    m, n = F.shape
    comp = "forces fx, fy, fz" if m == 3 else "wrench components fx, fy, fz, mx, my, mz"
    rank, cond = _design_rank(F)
    if rank < m:
        raise DesignError(
            f"the loads span rank {rank} but {m} linearly independent load directions are needed "
            f"({comp}) to determine a {m}x{m} stiffness; add load cases along the missing directions",
            source=name if name != "forces" else None,
        )
    flags: list[str] = []
    if cond > CONDITION_WARN:
        msg = f"badly conditioned load design (condition number {cond:.3g}): K is sensitive to noise"
        warnings.warn(msg, IllConditionedWarning, stacklevel=3)  # identify_stiffness's caller
        flags.append(msg)
    Fa = np.vstack([F, np.ones((1, n))]) if offset else F
    q = Fa.shape[0]
    if offset and np.linalg.matrix_rank(Fa / np.linalg.norm(Fa, axis=1, keepdims=True)) < q:
        raise DesignError(
            "with an offset the loads must not all lie on one plane that misses the origin "
            "(the offset and the stiffness cannot be told apart); add load cases of other magnitudes",
            source=name if name != "forces" else None,
        )
    return rank, cond, Fa, flags


def _check_displacements(D: np.ndarray, m: int, source: str | None) -> None:
    """Refuse displacements that cannot give a finite stiffness: all zero, or too few directions."""
    dmax = float(np.abs(D[:3]).max())
    if dmax < DISPLACEMENT_FLOOR_MM:
        what = "zero" if dmax == 0 else f"below {DISPLACEMENT_FLOOR_MM:g} mm (largest {dmax:.3g} mm)"
        raise DesignError(
            f"every displacement is {what}: nothing moved, so no finite stiffness can be identified "
            "(are the displacements in mm? did the sensor or the target follow the robot?)",
            source=source,
        )
    drank, _ = _design_rank(D)
    if drank < m:
        comp = "dx, dy, dz" if m == 3 else "dx, dy, dz, rx, ry, rz"
        raise DesignError(
            f"the displacements span rank {drank} but {m} independent directions ({comp}) are needed: "
            "K would be infinite along the others (the same displacement for every load, a component "
            "always zero, or a stuck sensor?)",
            source=source,
        )


def _no_finite_stiffness(F: np.ndarray, D: np.ndarray) -> str:
    """Why the estimate overflowed or was singular, for data that passed the design checks."""
    fmax = float(np.abs(F[:3]).max())
    dmax = float(np.abs(D[:3]).max())
    return (
        f"no finite stiffness from displacements of at most {dmax:.3g} mm under forces of at most "
        f"{fmax:.3g} N: their ratio is beyond floating-point range; are the forces in N and the "
        "displacements in mm?"
    )


def _compliance_fit(F, D, Fa, Sd, Sf):
    """The (augmented) compliance estimate Ca, the displacement covariances it weighted with
    (S_eff, None when none given), the weights W and the covariance of C.ravel() (None without
    covariances): the weighted fit when covariances are given, iterated on the forces' share."""
    m, n = F.shape
    q = Fa.shape[0]
    if Sd is None:
        W = np.broadcast_to(np.eye(m), (n, m, m))
        return D @ Fa.T @ np.linalg.inv(Fa @ Fa.T), None, W, None
    S_eff = Sd.copy()
    W = np.linalg.inv(S_eff)
    Ca, covCa = _gls_compliance(Fa, D, W)
    if Sf is not None:
        for _ in range(3):
            S_eff = Sd + np.einsum("ij,njk,lk->nil", Ca[:, :m], Sf, Ca[:, :m])
            W = np.linalg.inv(S_eff)
            Ca, covCa = _gls_compliance(Fa, D, W)
    keep = np.array([i * q + j for i in range(m) for j in range(m)])
    return Ca, S_eff, W, covCa[np.ix_(keep, keep)]


def _stiffness(method: str, C, F, Dm, W, S_eff, flags: list[str]):
    """K by the method, and the symmetric fit's covariance of C (None for the others)."""
    covC_spd = None
    if method == "compliance":
        K = np.linalg.inv(C)
    elif method == "paper":
        K = F @ Dm.T @ np.linalg.inv(Dm @ Dm.T)  # reference paper, eq. 10
    else:
        Cs, covC_spd, spd_active = _spd_compliance(F, Dm, W, S_eff)
        K = np.linalg.inv(Cs)
        K = 0.5 * (K + K.T)
        if spd_active:
            flags.append(
                "spd constraint active: the unconstrained symmetric fit was not positive definite; "
                "the data are not those of an admissible stiffness"
            )
    if not np.all(np.isfinite(K)):  # numpy's linalg returns inf/NaN without raising
        raise np.linalg.LinAlgError("K is not finite")
    return K, covC_spd


def _chi2_flag(R, W, m: int, n: int, dof: int, flags: list[str]) -> float | None:
    """The reduced chi-square of the residuals with the given uncertainties (None without
    residual degrees of freedom); a flag when they exceed them."""
    chi2 = float(sum(R[:, i] @ W[i] @ R[:, i] for i in range(n)))
    if dof <= 0:
        return None
    chi2_red = chi2 / (m * dof)
    p = chi2_sf(chi2, m * dof)
    if p < 0.01:
        flags.append(
            f"residuals exceed the given displacement uncertainty "
            f"(reduced chi-square {chi2_red:.3g}, p = {p:.2g})"
        )
    return chi2_red


def _noise_covariance(method, K, R, F, Fa, Dm, W, S_eff, covC, covC_spd, dof, flags):
    """K's covariance from the given uncertainties, else from the residuals: (sigma, K_cov,
    dof_eff, chi2_red). To first order the paper's estimator has the same covariance as the
    compliance one (dK = -K E F^T (F F^T)^-1 K for both); the symmetric fit has its own
    (smaller) one."""
    m, n = F.shape
    J = _inverse_jacobian(K)
    if S_eff is not None:
        chi2_red = _chi2_flag(R, W, m, n, dof, flags)
        if method == "spd":
            covC = covC_spd
        return S_eff.mean(axis=0), J @ covC @ J.T, np.full((m, m), np.inf), chi2_red
    if dof > 0:
        sigma = R @ R.T / dof
        P = np.linalg.inv(Fa @ Fa.T)[:m, :m]
        if method == "spd":
            _, covC, _ = _spd_compliance(F, Dm, W, np.broadcast_to(sigma, (n, m, m)))
            dof_eff = np.full((m, m), float(dof))  # conservative: Satterthwaite >= dof
        else:
            covC = np.kron(sigma, P)  # row-major vec: Cov(C[i, :], C[j, :]) = sigma_ij P
            dof_eff = _satterthwaite(J, P, sigma, dof).reshape(m, m)
        return sigma, J @ covC @ J.T, dof_eff, None
    flags.append(
        f"no residual degrees of freedom ({n} load cases for {Fa.shape[0]} unknowns per component): "
        "the uncertainty of K is unknown; add load cases or give displacement uncertainties"
    )
    return np.full((m, m), np.nan), np.full((m * m, m * m), np.nan), np.full((m, m), np.nan), None


def _with_common(common, K_cov, dof_eff, F, Fa, Dm, K, W, given, method, offset):
    """K's covariance with the common error's share, the effective degrees of freedom
    (Welch-Satterthwaite with that share known: nu = (v_noise + v_common)^2 nu / v_noise^2)
    and the share (K_cov_common)."""
    m = F.shape[0]
    dK = _common_sensitivity(common[0], F, Fa, Dm, K, W, given, method=method, offset=offset)
    K_cov_common = dK @ common[1] @ dK.T
    K_cov_common = 0.5 * (K_cov_common + K_cov_common.T)
    vn = np.diag(K_cov).reshape(m, m)
    vt = vn + np.diag(K_cov_common).reshape(m, m)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = (vt / np.where(vn > 0, vn, 1.0)) ** 2
        dof_eff = np.where(np.isnan(vn), np.nan, np.where(vn > 0, dof_eff * ratio, np.inf))
    return K_cov + K_cov_common, dof_eff, K_cov_common


def _estimate(
    F: np.ndarray,
    D: np.ndarray,
    Fa: np.ndarray,
    Sd: np.ndarray | None,
    Sf: np.ndarray | None,
    common: tuple[np.ndarray, np.ndarray] | None,
    *,
    method: str,
    offset: bool,
    rank: int,
    cond: float,
    flags: list[str],
) -> StiffnessFit:
    """The estimate of :func:`identify_stiffness` once its inputs are checked."""
    m, n = F.shape
    dof = n - Fa.shape[0]
    Ca, S_eff, W, covC = _compliance_fit(F, D, Fa, Sd, Sf)
    C = Ca[:, :m]
    b_off = Ca[:, m] if offset else None
    # The paper's and the symmetric estimators work on the offset-corrected displacements.
    Dm = D - b_off[:, None] if offset else D
    K, covC_spd = _stiffness(method, C, F, Dm, W, S_eff, flags)
    Cm = np.linalg.inv(K)
    R = Dm - Cm @ F
    rms = np.sqrt(np.mean(R**2, axis=1))
    sigma, K_cov, dof_eff, chi2_red = _noise_covariance(
        method, K, R, F, Fa, Dm, W, S_eff, covC, covC_spd, dof, flags
    )
    K_cov_common = None
    if common is not None:
        K_cov, dof_eff, K_cov_common = _with_common(
            common, K_cov, dof_eff, F, Fa, Dm, K, W, Sd is not None, method, offset
        )
    K_std = np.sqrt(np.clip(np.diag(K_cov), 0, None)).reshape(m, m)
    finite = bool(np.all(np.isfinite(K_cov)))
    # The test's law: Hotelling's with Sigma estimated from the residuals, chi-square when given.
    cov_dof = None if Sd is not None else dof
    flags.extend(physical_flags(K, K_cov if finite else None, dof=cov_dof, K_cov_common=K_cov_common))
    return StiffnessFit(
        K=K,
        K_cov=K_cov,
        K_std=K_std,
        C=Cm,
        method=method,
        rank=rank,
        condition=cond,
        residuals=R,
        residual_rms=rms,
        dof=dof,
        sigma=sigma,
        dof_effective=dof_eff,
        chi2_reduced=chi2_red,
        flags=tuple(flags),
        offset=b_off,
        K_cov_common=K_cov_common,
        cov_dof=cov_dof,
    )


def _common_sensitivity(
    G: np.ndarray,
    F: np.ndarray,
    Fa: np.ndarray,
    Dm: np.ndarray,
    K: np.ndarray,
    W: np.ndarray,
    given: bool,
    *,
    method: str,
    offset: bool,
) -> np.ndarray:
    """d K.ravel() / d c (m*m, p) when the displacements move by G[i] dc (exact at fixed weights).

    Each estimator is differentiated as computed: the (weighted) compliance fit is linear in
    D; the symmetric fit too while its positive-definite constraint is inactive (first order
    otherwise); the paper's K = F Dm^T (Dm Dm^T)^-1 by the product rule. With an offset, Dm's
    perturbation is the displacements' minus the offset's.
    """
    n, m, p = G.shape
    J = _inverse_jacobian(K)
    P = np.linalg.inv(Fa @ Fa.T)
    if method == "spd":
        B = _sym_basis(m)
        eye = np.eye(m)
        A = [np.kron(eye, F[:, i][None, :]) @ B for i in range(n)]
        Hinv = np.linalg.inv(sum(A[i].T @ W[i] @ A[i] for i in range(n)))
    else:
        A, B, Hinv = [], None, None
    DDinv = np.linalg.inv(Dm @ Dm.T) if method == "paper" else None
    out = np.empty((m * m, p))
    for k in range(p):
        dD = G[:, :, k].T  # (m, n)
        if given:
            dCa = _gls_compliance(Fa, dD, W)[0]
        else:
            dCa = dD @ Fa.T @ P
        dDm = dD - dCa[:, m][:, None] if offset else dD
        if method == "compliance":
            out[:, k] = J @ dCa[:, :m].ravel()
        elif method == "paper":
            dK = F @ dDm.T @ DDinv - K @ (dDm @ Dm.T + Dm @ dDm.T) @ DDinv
            out[:, k] = dK.ravel()
        else:
            x = Hinv @ sum(A[i].T @ W[i] @ dDm[:, i] for i in range(n))
            out[:, k] = J @ (B @ x)
    return out
