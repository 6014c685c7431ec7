"""Repeat statistics after ISO 5725-2 (precision of a measurement method).

A *condition* (ISO 5725's "laboratory": a position, a day, an operator, a
load case...) holds n_i repeated measurements of the same quantity. From p
conditions this module computes:

- per condition: mean, standard deviation, n;
- the repeatability standard deviation s_r and limit r = 2.8 s_r;
- the between-condition standard deviation s_L, the reproducibility standard
  deviation s_R = sqrt(s_L^2 + s_r^2) and limit R = 2.8 s_R;
- Mandel's h (between) and k (within) statistics, Cochran's C (largest
  variance), and the single Grubbs statistic (largest and smallest mean);
- stragglers (5 %) and outliers (1 %) judged by critical values computed
  from the t and F distributions (ISO 5725-2, 7.3.3-7.3.4 and Annex B
  formulas), not read from tables.

It is also the one home of the probability laws the package uses (:func:`chi2_sf`,
:func:`chi2_ppf`, :func:`t_ppf`, :func:`f_ppf`, :func:`f_sf`, :func:`hotelling_t2_sf`):
SciPy's, with ``scipy.stats`` imported on first use (it takes 0.35 s, and most commands never need it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ConditionStats",
    "PrecisionResult",
    "precision",
    "describe",
    "mandel_h_critical",
    "mandel_k_critical",
    "cochran_critical",
    "grubbs_critical",
    "chi2_sf",
    "chi2_ppf",
    "t_ppf",
    "f_ppf",
    "f_sf",
    "hotelling_t2_sf",
    "ExcessDispersion",
    "excess_dispersion",
    "holm_rejects",
]


def _laws():
    from scipy import stats  # on first use: 0.35 s that most commands never need

    return stats


def _value(v):
    """A float for one value, an array for several (the laws take arrays elementwise)."""
    return float(v) if np.ndim(v) == 0 else np.asarray(v, dtype=np.float64)


def chi2_sf(x, dof):
    """P(X > x) for X chi-squared with ``dof`` degrees of freedom (elementwise over arrays)."""
    return _value(_laws().chi2.sf(x, dof))


def chi2_ppf(q, dof):
    """The ``q`` quantile of the chi-squared law with ``dof`` degrees of freedom (elementwise over arrays)."""
    return _value(_laws().chi2.ppf(q, dof))


def t_ppf(q, dof):
    """The ``q`` quantile of Student's t with ``dof`` degrees of freedom (elementwise over arrays)."""
    return _value(_laws().t.ppf(q, dof))


def f_ppf(q, dfn, dfd):
    """The ``q`` quantile of Fisher's F with (``dfn``, ``dfd``) degrees of freedom (elementwise)."""
    return _value(_laws().f.ppf(q, dfn, dfd))


def f_sf(x, dfn, dfd):
    """P(X > x) for X of Fisher's F law with (``dfn``, ``dfd``) degrees of freedom (elementwise)."""
    return _value(_laws().f.sf(x, dfn, dfd))


def hotelling_t2_sf(t2, q: int, dof):
    """P(T^2 > t2) for Hotelling's T^2 = a^T S^-1 a of a q-vector a ~ N(0, V) and an
    independent covariance estimate S ~ Wishart(V, dof) / dof: (dof - q + 1) T^2 / (q dof)
    follows F(q, dof - q + 1). ``dof`` may be fractional (an effective one) and infinite (V
    known: the chi-square law of q degrees of freedom); NaN when dof < q (S then singular
    by construction, the law undefined). Elementwise over ``t2`` and ``dof``."""
    t2 = np.asarray(t2, dtype=np.float64)
    dof = np.asarray(dof, dtype=np.float64)
    known = np.isinf(dof)
    d2 = np.where(known | (dof < q), 1.0, dof - q + 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p_f = f_sf(t2 * d2 / (q * np.where(known, 1.0, dof)), q, d2)
    p = np.where(known, chi2_sf(t2, q), np.where(dof < q, np.nan, p_f))
    return _value(p)


@dataclass(frozen=True)
class ExcessDispersion:
    """Result of :func:`excess_dispersion`.

    Attributes
    ----------
    cov : ndarray, shape (p, p)
        The excess covariance D (positive semi-definite; zeros when the scatter is what the
        covariances predict).
    ratio : float
        sum e_i^T P_i^-1 e_i / (p (n - 1)) over the vectors kept: the variance ratio (about 1
        when the P_i hold).
    p_value : float
        Of that sum under the chi-square law of p (n - 1) degrees of freedom.
    left_out : tuple of int
        Indices of the vectors left out of the estimate as outliers.
    """

    cov: np.ndarray
    ratio: float
    p_value: float
    left_out: tuple[int, ...] = ()


def _excess_moments(q: float, EE: np.ndarray, SP: np.ndarray, n: int, level: float):
    """D = the positive part of EE / (n - 1) - SP / n (EE = sum e e^T, SP = sum P over n vectors),
    zero unless q = sum e^T P^-1 e is significant at ``level`` under the chi-square law of
    p (n - 1) degrees of freedom; with the ratio q / (p (n - 1)) and the p-value."""
    p = len(EE)
    dof = p * (n - 1)
    p_value = chi2_sf(q, dof)
    if p_value > level:
        return np.zeros((p, p)), q / dof, p_value
    M = EE / (n - 1) - SP / n
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * np.maximum(w, 0.0)) @ V.T, q / dof, p_value


def excess_dispersion(
    residuals, covs, *, level: float = 0.05, outlier_quantile: float = 0.9999
) -> ExcessDispersion:
    """The covariance D of what scatters vectors beyond their own covariances: e_i ~ N(0, P_i + D).

    The method of moments of a random-effects model (as in a meta-analysis's between-study
    variance): D is the positive part of sum e_i e_i^T / (n - 1) - mean P_i (n - 1: the e_i are
    deviations from an estimate fitted to them), and zero when sum e_i^T P_i^-1 e_i is within its
    chi-square law (p (n - 1) degrees of freedom) at ``level``, so that vectors whose covariances
    hold give D = 0 (not the positive part of chance scatter). Robust to a gross bad vector: the
    one farthest outside D estimated without it is left out and D estimated again (at most a
    tenth of the vectors, at least one, while more than p + 1 remain) when its e^T (P + D)^-1 e
    is above the ``outlier_quantile`` of the law of that statistic for a D estimated from the
    other m vectors (Hotelling's, nu p / (nu - p + 1) F(p, nu - p + 1) with nu = m - 1: 13
    vectors of 6, 390 where chi-square's is 28): a D estimated from a dozen vectors is itself
    uncertain, and leaving out a vector it merely fails to cover would make D too small.

    Parameters
    ----------
    residuals : array_like, shape (n, p)
    covs : array_like, shape (n, p, p)
        Each vector's covariance (positive definite).

    Returns
    -------
    ExcessDispersion

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> P = np.stack([np.eye(2)] * 400)
    >>> e = rng.normal(size=(400, 2)) * [2.0, 1.0]  # variances 4 and 1: 3 and 0 in excess
    >>> np.round(np.diag(excess_dispersion(e, P).cov), 1)
    array([3.1, 0. ])
    """
    e = np.asarray(residuals, dtype=np.float64)
    P = np.asarray(covs, dtype=np.float64)
    n, p = e.shape
    if P.shape != (n, p, p):
        raise ValueError(f"covs must be ({n}, {p}, {p}) for residuals {e.shape}, got {P.shape}")
    q = np.array([x @ np.linalg.solve(c, x) for x, c in zip(e, P, strict=True)])
    outer = e[:, :, None] * e[:, None, :]
    keep = list(range(n))
    while len(keep) - 1 > p + 1 and n - len(keep) < max(1, n // 10):
        # A vector is left out when beyond what a D estimated from the other m can explain:
        # e^T D^-1 e of a new vector follows Hotelling's law (nu p / (nu - p + 1)) F(p, nu - p + 1),
        # nu = m - 1, when D dominates (and chi-square, below it, when P does).
        m = len(keep) - 1
        worst, worst_i = (m - 1) * p / (m - p) * f_ppf(outlier_quantile, p, m - p), None
        Q, EE, SP = q[keep].sum(), outer[keep].sum(axis=0), P[keep].sum(axis=0)
        for i in keep:
            D, _, _ = _excess_moments(Q - q[i], EE - outer[i], SP - P[i], m, level)
            c = float(e[i] @ np.linalg.solve(P[i] + D, e[i]))
            if c > worst:
                worst, worst_i = c, i
        if worst_i is None:
            break
        keep.remove(worst_i)
    D, ratio, p_value = _excess_moments(
        q[keep].sum(), outer[keep].sum(axis=0), P[keep].sum(axis=0), len(keep), level
    )
    return ExcessDispersion(D, ratio, p_value, tuple(i for i in range(n) if i not in keep))


STRAGGLER_ALPHA = 0.05
OUTLIER_ALPHA = 0.01


def holm_rejects(p_values, alpha: float) -> np.ndarray:
    """Holm's step-down test of a family of hypotheses at family-wise level ``alpha``: the
    k-th smallest p-value (k = 0, 1, ...) is rejected while it is below alpha / (m - k), m
    the number of finite p-values (NaN: not tested, never rejected). Returns the mask of
    rejected hypotheses (Holm, Scand. J. Statist. 6, 65-70, 1979)."""
    p = np.asarray(p_values, dtype=np.float64)
    out = np.zeros(p.shape, dtype=bool)
    tested = np.flatnonzero(np.isfinite(p))
    m = tested.size
    for k, i in enumerate(tested[np.argsort(p[tested], kind="stable")]):
        if not p[i] < alpha / (m - k):
            break
        out[i] = True
    return out


def _check_p(p: int, minimum: int) -> None:
    if int(p) != p or p < minimum:
        raise ValueError(f"p (number of conditions) must be an integer >= {minimum}, got {p}")


def mandel_h_critical(p: int, alpha: float) -> float:
    """Critical value of Mandel's h for p conditions at level alpha (two-sided).

    h = (p - 1) t / sqrt(p (t^2 + p - 2)), t the upper alpha/2 quantile of
    Student's t with p - 2 degrees of freedom.
    """
    _check_p(p, 3)
    t = t_ppf(1 - alpha / 2, p - 2)
    return float((p - 1) * t / np.sqrt(p * (t * t + p - 2)))


def mandel_k_critical(p: int, n: int, alpha: float) -> float:
    """Critical value of Mandel's k for p conditions of n repeats at level alpha.

    k = sqrt(p / (1 + (p - 1) / F)), F the upper alpha quantile of
    F(n - 1, (p - 1)(n - 1)).
    """
    _check_p(p, 2)
    if n < 2:
        raise ValueError(f"n (repeats per condition) must be >= 2, got {n}")
    f = f_ppf(1 - alpha, n - 1, (p - 1) * (n - 1))
    return float(np.sqrt(p / (1 + (p - 1) / f)))


def cochran_critical(p: int, n: int, alpha: float) -> float:
    """Critical value of Cochran's C for p conditions of n repeats at level alpha.

    C = 1 / (1 + (p - 1) / F), F the upper alpha/p quantile of
    F(n - 1, (p - 1)(n - 1)).
    """
    _check_p(p, 2)
    if n < 2:
        raise ValueError(f"n (repeats per condition) must be >= 2, got {n}")
    f = f_ppf(1 - alpha / p, n - 1, (p - 1) * (n - 1))
    return float(1 / (1 + (p - 1) / f))


def grubbs_critical(p: int, alpha: float) -> float:
    """Critical value of the single Grubbs statistic for p values at level alpha.

    G = (p - 1) / sqrt(p) * sqrt(t^2 / (p - 2 + t^2)), t the upper alpha/(2p)
    quantile of Student's t with p - 2 degrees of freedom.
    """
    _check_p(p, 3)
    t = t_ppf(1 - alpha / (2 * p), p - 2)
    return float((p - 1) / np.sqrt(p) * np.sqrt(t * t / (p - 2 + t * t)))


@dataclass(frozen=True)
class ConditionStats:
    """Mean, standard deviation (n - 1 in the denominator) and count of one condition."""

    mean: float
    std: float
    n: int


def describe(values) -> ConditionStats:
    """Mean, standard deviation and n of repeated values (NaN are refused)."""
    x = np.asarray(values, dtype=np.float64).ravel()
    if x.size == 0:
        raise ValueError("no values")
    if not np.all(np.isfinite(x)):
        raise ValueError("values contain NaN or infinite entries")
    std = float(np.std(x, ddof=1)) if x.size > 1 else float("nan")
    return ConditionStats(float(np.mean(x)), std, int(x.size))


@dataclass(frozen=True)
class PrecisionResult:
    """ISO 5725-2 precision of a set of conditions (see :func:`precision`)."""

    conditions: tuple[ConditionStats, ...]
    grand_mean: float
    s_r: float
    r: float
    s_L: float
    s_R: float
    R: float
    h: np.ndarray
    k: np.ndarray
    cochran_C: float | None
    grubbs_high: float | None
    grubbs_low: float | None
    critical: dict[str, tuple[float, float]]
    stragglers: tuple[str, ...]
    outliers: tuple[str, ...]


def _between_conditions(n: np.ndarray, means: np.ndarray, s_r2: float) -> tuple[float, np.ndarray]:
    """The between-condition variance s_L^2 and Mandel's h of each condition (0 for one)."""
    p = len(means)
    if p == 1:
        return 0.0, np.zeros(p)
    N = n.sum()
    grand = float((n * means).sum() / N)
    s_d2 = float((n * (means - grand) ** 2).sum() / (p - 1))
    nbar = float((N - (n**2).sum() / N) / (p - 1))
    s_L2 = max((s_d2 - s_r2) / nbar, 0.0)
    dev = means - means.mean()
    sb = np.sqrt((dev**2).sum() / (p - 1))
    return s_L2, (dev / sb if sb > 0 else np.zeros(p))


class _ConsistencyTests:
    """ISO 5725-2's consistency tests: their (5 %, 1 %) critical values and the conditions
    found beyond them (stragglers, outliers)."""

    def __init__(self, labels: list[str]):
        self.labels = labels
        self.p = len(labels)
        self.critical: dict[str, tuple[float, float]] = {}
        self.stragglers: list[str] = []
        self.outliers: list[str] = []

    def _judge(self, stat: float, crit: tuple[float, float], what: str) -> None:
        if stat > crit[1]:
            self.outliers.append(what)
        elif stat > crit[0]:
            self.stragglers.append(what)

    def means(self, h: np.ndarray, means: np.ndarray) -> tuple[float | None, float | None]:
        """Mandel's h and Grubbs' tests on the condition means (three conditions or more):
        Grubbs' G of the highest and of the lowest mean (None: not computed)."""
        p, labels, critical = self.p, self.labels, self.critical
        if p < 3:
            return None, None
        critical["h"] = (mandel_h_critical(p, STRAGGLER_ALPHA), mandel_h_critical(p, OUTLIER_ALPHA))
        critical["G"] = (grubbs_critical(p, STRAGGLER_ALPHA), grubbs_critical(p, OUTLIER_ALPHA))
        for i in range(p):
            self._judge(abs(h[i]), critical["h"], f"{labels[i]}: Mandel h = {h[i]:.3f}")
        sd_means = float(np.std(means, ddof=1))
        if not sd_means > 0:
            return None, None
        grubbs_hi = float((means.max() - means.mean()) / sd_means)
        grubbs_lo = float((means.mean() - means.min()) / sd_means)
        self._judge(
            grubbs_hi, critical["G"], f"{labels[int(means.argmax())]}: Grubbs G = {grubbs_hi:.3f} (high)"
        )
        self._judge(
            grubbs_lo, critical["G"], f"{labels[int(means.argmin())]}: Grubbs G = {grubbs_lo:.3f} (low)"
        )
        return grubbs_hi, grubbs_lo

    def variances(self, k: np.ndarray, stds: np.ndarray, ssum: float, n_rep: int) -> float | None:
        """Mandel's k and Cochran's tests on the condition variances (two conditions or more,
        critical values for ``n_rep`` repeats): Cochran's C (None: not computed)."""
        p, labels, critical = self.p, self.labels, self.critical
        if p < 2:
            return None
        critical["k"] = (
            mandel_k_critical(p, n_rep, STRAGGLER_ALPHA),
            mandel_k_critical(p, n_rep, OUTLIER_ALPHA),
        )
        critical["C"] = (
            cochran_critical(p, n_rep, STRAGGLER_ALPHA),
            cochran_critical(p, n_rep, OUTLIER_ALPHA),
        )
        for i in range(p):
            self._judge(k[i], critical["k"], f"{labels[i]}: Mandel k = {k[i]:.3f}")
        if not ssum > 0:
            return None
        cochran_C = float(stds.max() ** 2 / ssum)
        self._judge(cochran_C, critical["C"], f"{labels[int(stds.argmax())]}: Cochran C = {cochran_C:.3f}")
        return cochran_C


def precision(groups: Sequence[Sequence[float]], labels: Sequence[str] | None = None) -> PrecisionResult:
    """ISO 5725-2 analysis of repeated measurements under p conditions.

    Parameters
    ----------
    groups : sequence of p sequences
        The repeated values of each condition (any unit; results in the same).
    labels : sequence of str, optional
        Names of the conditions for the straggler and outlier messages.

    Returns
    -------
    PrecisionResult
        ``critical`` maps ``"h"``, ``"k"``, ``"C"``, ``"G"`` to the
        (5 %, 1 %) critical values; ``stragglers`` and ``outliers`` list the
        conditions beyond them, with the test that found each. With unequal
        repeat counts the k and C critical values use the mean n, rounded.
    """
    p = len(groups)
    if p < 1:
        raise ValueError("at least one condition is needed")
    labels = list(labels) if labels is not None else [f"condition {i + 1}" for i in range(p)]
    if len(labels) != p:
        raise ValueError(f"{len(labels)} labels for {p} conditions")
    cs = tuple(describe(g) for g in groups)
    n = np.array([c.n for c in cs], dtype=float)
    means = np.array([c.mean for c in cs])
    stds = np.array([c.std for c in cs])
    if np.any(n < 2):
        bad = [labels[i] for i in np.flatnonzero(n < 2)]
        raise ValueError(f"every condition needs at least 2 repeats; too few in: {', '.join(bad)}")
    N = n.sum()
    grand = float((n * means).sum() / N)
    s_r2 = float(((n - 1) * stds**2).sum() / (n - 1).sum())
    s_L2, h = _between_conditions(n, means, s_r2)
    ssum = (stds**2).sum()
    k = stds * np.sqrt(p) / np.sqrt(ssum) if ssum > 0 else np.zeros(p)
    s_r = float(np.sqrt(s_r2))
    s_R = float(np.sqrt(s_L2 + s_r2))
    tests = _ConsistencyTests(labels)
    grubbs_hi, grubbs_lo = tests.means(h, means)
    cochran_C = tests.variances(k, stds, ssum, int(round(n.mean())))
    critical, stragglers, outliers = tests.critical, tests.stragglers, tests.outliers
    return PrecisionResult(
        conditions=cs,
        grand_mean=grand,
        s_r=s_r,
        r=2.8 * s_r,
        s_L=float(np.sqrt(s_L2)),
        s_R=s_R,
        R=2.8 * s_R,
        h=h,
        k=k,
        cochran_C=cochran_C,
        grubbs_high=grubbs_hi,
        grubbs_low=grubbs_lo,
        critical=critical,
        stragglers=tuple(stragglers),
        outliers=tuple(outliers),
    )
