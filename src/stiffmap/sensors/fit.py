"""Load-displacement fit, static error and hysteresis of one recording.

The plateaus give pairs (F_i, x_i): load in N, displacement along the sensor
axis in mm. The model is the straight line x = a + c F (a the intercept, mm; c
the compliance along the axis, mm/N; the stiffness k = 1/c, N/mm), fitted by
ordinary least squares: the loads are known far better than the displacements
(0.05 kgf dynamometer resolution), so the errors are in x and this regression is
unbiased in c. Standard errors come from the residuals (n - 2 degrees of
freedom), the stiffness's by the delta method (s_k = s_c / c^2), and the
confidence intervals from Student's t. The static error at a reference load F_ref
is the displacement it causes from the unloaded position, c F_ref (the
milling study's static error at 50 kgf = 490.5 N, its Figs. 11-14).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..stats import t_ppf

__all__ = ["LinearFit", "Hysteresis", "fit_load_displacement", "hysteresis", "branches"]


@dataclass(frozen=True)
class LinearFit:
    """x = intercept + compliance * F, by least squares.

    Attributes
    ----------
    compliance_mm_per_n, compliance_std_mm_per_n : float
    intercept_mm, intercept_std_mm : float
    stiffness_n_per_mm, stiffness_std_n_per_mm : float
        1 / compliance and its standard error (delta method).
    r2 : float
        Coefficient of determination.
    level : float
        Confidence level of the intervals.
    compliance_ci_mm_per_n, stiffness_ci_n_per_mm : tuple of float
        Confidence intervals (the stiffness's is inf-bounded when the compliance's
        interval contains 0).
    residuals_mm : ndarray, shape (n,)
    dof : int
        n - 2; the standard errors are NaN when it is 0.
    n : int
        Number of plateaus.
    """

    compliance_mm_per_n: float
    compliance_std_mm_per_n: float
    intercept_mm: float
    intercept_std_mm: float
    stiffness_n_per_mm: float
    stiffness_std_n_per_mm: float
    r2: float
    level: float
    compliance_ci_mm_per_n: tuple[float, float]
    stiffness_ci_n_per_mm: tuple[float, float]
    residuals_mm: np.ndarray
    dof: int
    n: int

    def static_error_mm(self, load_n: float) -> tuple[float, float]:
        """Displacement caused by ``load_n`` from the unloaded position, and its standard error, mm."""
        return self.compliance_mm_per_n * load_n, self.compliance_std_mm_per_n * abs(load_n)


def _ratio(a: float, b: float) -> float:
    """``a / b`` as IEEE arithmetic gives it (inf for an overflow), never a Python exception."""
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        return float(np.float64(a) / np.float64(b))


def fit_load_displacement(load_n, displacement_mm, *, level: float = 0.95) -> LinearFit:
    """Least-squares line through load-displacement pairs.

    Parameters
    ----------
    load_n : array_like, shape (n,), N
    displacement_mm : array_like, shape (n,), mm
    level : float
        Confidence level of the intervals, in (0, 1).

    Returns
    -------
    LinearFit

    Raises
    ------
    ValueError
        Fewer than two pairs, non-finite values, or all loads equal.
    """
    F = np.asarray(load_n, dtype=np.float64).ravel()
    x = np.asarray(displacement_mm, dtype=np.float64).ravel()
    if F.shape != x.shape:
        raise ValueError(f"load_n and displacement_mm must have the same length, got {F.size} and {x.size}")
    if F.size < 2:
        raise ValueError(f"a line needs at least 2 load-displacement pairs, got {F.size}")
    if not (np.all(np.isfinite(F)) and np.all(np.isfinite(x))):
        raise ValueError("load_n and displacement_mm must be finite")
    if not (0 < level < 1):
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    n = F.size
    Fm, xm = F.mean(), x.mean()
    Sff = float(((F - Fm) ** 2).sum())
    if Sff <= (1e-12 * max(1.0, float(np.abs(F).max()))) ** 2 * n:
        raise ValueError(f"all loads are equal ({F[0]:.6g} N): no slope can be fitted")
    c = float(((F - Fm) * (x - xm)).sum() / Sff)
    a = float(xm - c * Fm)
    res = x - (a + c * F)
    dof = n - 2
    sst = float(((x - xm) ** 2).sum())
    r2 = 1.0 - float((res**2).sum()) / sst if sst > 0 else float("nan")
    if dof > 0:
        s2 = float((res**2).sum()) / dof
        sc = math.sqrt(s2 / Sff)
        sa = math.sqrt(s2 * (1.0 / n + Fm**2 / Sff))
        tq = t_ppf(0.5 + level / 2, dof)
    else:
        sc = sa = tq = float("nan")
    k = _ratio(1.0, c) if c != 0 else float("inf")
    sk = _ratio(sc, c * c) if c != 0 else float("nan")
    c_lo, c_hi = c - tq * sc, c + tq * sc
    if math.isfinite(c_lo) and (c_lo > 0 or c_hi < 0):
        k_ci = (_ratio(1.0, c_hi), _ratio(1.0, c_lo))
    elif math.isfinite(c_lo) and c > 0:
        k_ci = (_ratio(1.0, c_hi), math.inf)
    elif math.isfinite(c_lo) and c < 0:
        k_ci = (-math.inf, _ratio(1.0, c_lo))
    elif math.isfinite(c_lo):  # a zero slope: the interval of k is the whole line
        k_ci = (-math.inf, math.inf)
    else:
        k_ci = (float("nan"), float("nan"))
    return LinearFit(
        compliance_mm_per_n=c,
        compliance_std_mm_per_n=sc,
        intercept_mm=a,
        intercept_std_mm=sa,
        stiffness_n_per_mm=k,
        stiffness_std_n_per_mm=sk,
        r2=r2,
        level=level,
        compliance_ci_mm_per_n=(c_lo, c_hi),
        stiffness_ci_n_per_mm=k_ci,
        residuals_mm=res,
        dof=dof,
        n=n,
    )


def branches(load_n, *, tol_n: float) -> list[str]:
    """Label each plateau of a load sequence: start, loading, unloading or hold.

    Parameters
    ----------
    load_n : array_like, shape (n,), N, in time order
    tol_n : float
        Changes within +-tol_n are a hold.
    """
    F = np.asarray(load_n, dtype=np.float64).ravel()
    out = ["start"] if F.size else []
    for i in range(1, F.size):
        d = F[i] - F[i - 1]
        out.append("loading" if d > tol_n else "unloading" if d < -tol_n else "hold")
    return out


@dataclass(frozen=True)
class Hysteresis:
    """Largest gap between the unloading and the loading branch at equal load.

    Attributes
    ----------
    max_mm : float
        Unloading minus loading displacement where their difference is largest, mm.
    at_load_n : float
        The load where it is, N.
    ratio : float
        |max_mm| over the displacement span of the recording.
    """

    max_mm: float
    at_load_n: float
    ratio: float


def _branch_curve(F: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.unique(F)
    xm = np.array([x[F == f].mean() for f in u])
    return u, xm


def hysteresis(load_n, displacement_mm, labels, *, tol_n: float) -> Hysteresis | None:
    """Hysteresis between the loading and the unloading plateaus, when both exist.

    The loading branch holds every plateau reached by an increase of the load and
    the plateau it started from; the unloading branch likewise. Each branch is a
    piecewise-linear curve x(F); their difference is taken at every branch load
    inside the common load range.

    Parameters
    ----------
    load_n, displacement_mm : array_like, shape (n,)
    labels : sequence of str
        From :func:`branches`.
    tol_n : float
        Loads closer than this are taken as equal.

    Returns
    -------
    Hysteresis or None
        None when a branch has fewer than two distinct loads or the branches do not overlap.
    """
    F = np.asarray(load_n, dtype=np.float64).ravel()
    x = np.asarray(displacement_mm, dtype=np.float64).ravel()
    idx = {"loading": set(), "unloading": set()}
    for i, lab in enumerate(labels):
        if lab in idx:
            idx[lab].update((i - 1, i))
    curves = {}
    for lab, ii in idx.items():
        ii = sorted(ii)
        if len({round(F[i] / tol_n) for i in ii}) < 2:
            return None
        curves[lab] = _branch_curve(F[ii], x[ii])
    (Fl, xl), (Fu, xu) = curves["loading"], curves["unloading"]
    lo, hi = max(Fl[0], Fu[0]), min(Fl[-1], Fu[-1])
    if hi - lo < tol_n:
        return None
    grid = np.unique(np.concatenate([Fl, Fu]))
    grid = grid[(grid >= lo - 1e-9 * abs(lo)) & (grid <= hi + 1e-9 * abs(hi))]
    diff = np.interp(grid, Fu, xu) - np.interp(grid, Fl, xl)
    j = int(np.argmax(np.abs(diff)))
    span = float(x.max() - x.min())
    return Hysteresis(
        float(diff[j]), float(grid[j]), abs(float(diff[j])) / span if span > 0 else float("nan")
    )
