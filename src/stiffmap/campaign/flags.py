"""The flags on a vision campaign's K, decided over the whole campaign (``stiffmap run``).

Each position's K is identified with its own flags (:func:`stiffmap.identify.physical_flags`);
over a campaign:

- the **asymmetry** test (K - K^T against its covariance, estimated from the position's
  residuals: Hotelling's law with the effective degrees of freedom of
  :func:`stiffmap.identify.asymmetry_dof`, the calibration's share known) runs on every position
  and Holm's step-down procedure keeps the family-wise level at ``FAMILY_ALPHA`` (1 %) over
  the positions tested (:func:`stiffmap.stats.holm_rejects`): at 1 % per position, 48
  positions of a symmetric K would flag one or two by chance. A K without a covariance,
  identified with fewer residual degrees of freedom than its rows, or whose K - K^T
  covariance is singular (:func:`stiffmap.identify.asymmetry_p_value` NaN), is flagged by the fixed
  threshold (``ASYMMETRY_FLAG``, 10 %) of one K: a review flag, its uncertainty unknown;
- with the loads hung off the measured point (``loads.point_mm`` not zero) the asymmetry is
  not tested: the K they see is (C_tt + C_tr [r]x)^-1, not symmetric by construction
  (docs/models.md); one note says so;
- a K that is asymmetric (by the test), not positive definite or of det <= 0 (``HARD_FLAGS``)
  is a failure of the run (``stiffmap run`` exits 1, a ``warning:`` line per position, with
  the axis whose sign looks reversed); the other flags (Cochran's repeatability outliers, the
  load design's) are review flags, in the tables only.

The stored flags are rewritten with the campaign's decision (idempotent: a re-run over
reused positions decides again from their K and covariance).
"""

from __future__ import annotations

import numpy as np

from ..identify import ASYMMETRY_P, asymmetry_p_value, physical_flags, stiffness_indices
from ..stats import holm_rejects
from .spec import CampaignSpec
from .store import Store

__all__ = ["FAMILY_ALPHA", "HARD_FLAGS", "campaign_flags"]

#: The family-wise level of the asymmetry test over a campaign's positions (Holm).
FAMILY_ALPHA = ASYMMETRY_P
#: The flags (their first words) that make a position's K a failure of the run.
HARD_FLAGS = ("asymmetric", "not positive definite", "det <= 0")
_SIGN_HINT = "axis sign"


def campaign_flags(store: Store, spec: CampaignSpec) -> tuple[list[str], list[str]]:
    """Decide the asymmetry flags over the campaign, store every position's flags, and return
    the failures (one per position whose K has a ``HARD_FLAGS`` flag) and the notes."""
    rows = [r for r in store.stiffness_rows() if r.status == "ok" and r.K is not None]
    lever = spec.loads.point_mm if spec.loads is not None else None
    notes: list[str] = []
    if lever is not None and any(v != 0.0 for v in lever):
        asym: dict[int, tuple[str, bool]] = {}
        if rows:
            notes.append(
                "K's asymmetry is not tested: the loads hang at loads.point_mm = "
                f"({', '.join(f'{v:g}' for v in lever)}) mm from the measured point, where the K "
                "they see, (C_tt + C_tr [r]x)^-1, is not symmetric by construction"
            )
    else:
        asym = _asymmetry_flags(rows)
    failures = []
    for r in rows:
        old = list(r.flags or [])
        flags = [f for f in old if not f.startswith("asymmetric")]
        flag, tested = asym.get(r.position, (None, False))
        if flag is not None:
            flags.insert(0, flag)
        if flags != old:
            store.set_stiffness_flags(r.position, flags)
        hard = [f for f in flags if f.startswith(HARD_FLAGS) and (tested or f is not flag)]
        if hard:
            hard += [f for f in flags if f.startswith(_SIGN_HINT)]
            failures.append(f"position {r.position} ({r.x:g}, {r.y:g}, {r.z:g} mm): K {'; '.join(hard)}")
    return failures, notes


def _asymmetry_flags(rows) -> dict[int, tuple[str, bool]]:
    """The asymmetry flag of each position whose K is asymmetric, and whether a test said so:
    Holm's test at ``FAMILY_ALPHA`` over the positions with a covariance (True), the fixed
    threshold without one (False: a review flag, K's uncertainty being unknown)."""
    p = np.array([_p_value(r) for r in rows])
    tested = int(np.isfinite(p).sum())
    out = {}
    for r, pi, rejected in zip(rows, p, holm_rejects(p, FAMILY_ALPHA), strict=True):
        if rejected:
            out[r.position] = (
                f"asymmetric: |K-K^T|/|K| = {stiffness_indices(r.K).asymmetry:.3g}, beyond its "
                f"uncertainty (p = {pi:.2g}; Holm's test at {100 * FAMILY_ALPHA:g} % over the "
                f"campaign's {tested} positions)",
                True,
            )
        elif not np.isfinite(pi):
            out.update((r.position, (f, False)) for f in physical_flags(r.K) if f.startswith("asymmetric"))
    return out


def _p_value(r) -> float:
    """The asymmetry test's p-value of a position's K (NaN: not tested). Not tested without a
    finite covariance, nor with fewer residual degrees of freedom than K has rows: the
    displacements' covariance is then estimated from too few residuals to be of full rank,
    and K - K^T's covariance near singular makes any asymmetry look significant (a
    noise-free simulation of 4 loads, dof 1: 1 % asymmetric, p = 0)."""
    if r.K_cov is None or not np.all(np.isfinite(r.K_cov)) or (r.dof or 0) < r.K.shape[0]:
        return float("nan")
    return asymmetry_p_value(r.K, r.K_cov, r.dof, r.K_cov_calibration)
