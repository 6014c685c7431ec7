"""Stiffness identification from a forces CSV and a displacements CSV.

FORCES.csv has columns ``fx, fy, fz`` (N) and, for wrenches, ``mx, my, mz``
(N*mm); DISPLACEMENTS.csv has ``dx, dy, dz`` (mm) and optionally ``rx, ry, rz``
(rad), one row per load case in the same order. An optional ``repeat`` column
in DISPLACEMENTS.csv groups repeated measurements: each repeat holds one row
per load case, in the forces' order.

A 6x6 stiffness is identified when the forces carry moments and the
displacements carry rotations; with forces only, the translations give a 3x3
stiffness and rotations, if present, are not used (said in ``notes``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, StiffmapWarning
from ..identify import StiffnessFit, identify_stiffness
from ..io import read_csv_columns
from ..loads import MAX_FORCE_N, MAX_MOMENT_NMM
from ..stats import ConditionStats, describe
from ..stiffness import MAX_DISPLACEMENT_MM, MAX_ROTATION_RAD

__all__ = ["IdentifyReport", "identify_from_files", "FORCE_COLUMNS", "DISP_COLUMNS"]

FORCE_COLUMNS = ("fx", "fy", "fz", "mx", "my", "mz")
DISP_COLUMNS = ("dx", "dy", "dz", "rx", "ry", "rz")


@dataclass(frozen=True)
class IdentifyReport:
    """What ``stiffmap identify`` computes.

    Attributes
    ----------
    fit : StiffnessFit
    forces : ndarray, shape (m, n_loads)
    repeats : int
        Repeats per load case.
    per_load : list of ConditionStats
        Displacement norm (mm) of each load case over its repeats.
    notes : tuple of str
        Remarks on how the files were read.
    """

    fit: StiffnessFit
    forces: np.ndarray
    repeats: int
    per_load: list[ConditionStats]
    notes: tuple[str, ...] = field(default_factory=tuple)

    def to_dict(self, forces_file: str = "", displacements_file: str = "") -> dict:
        """The JSON object of ``stiffmap identify --json``."""
        f = self.fit
        idx = f.indices
        lo, hi = f.confidence_interval(0.95)
        return {
            "forces_file": forces_file,
            "displacements_file": displacements_file,
            "method": f.method,
            "K": f.K,
            "K_std": f.K_std,
            "K_ci95": [lo, hi],
            "det": idx.det,
            "eigenvalues": idx.eigenvalues,
            "principal_directions": idx.directions.T,
            "min_principal": idx.min_principal,
            "K_condition": idx.condition,
            "asymmetry": idx.asymmetry,
            "asymmetry_p": f.asymmetry_p,
            "flags": list(f.flags),
            "rank": f.rank,
            "condition": f.condition,
            "dof": f.dof,
            "residual_rms": f.residual_rms,
            "n_load_cases": int(self.forces.shape[1]),
            "repeats": self.repeats,
            "load_cases": [
                {
                    "force": self.forces[:, i],
                    "displacement_norm_mean": c.mean,
                    "displacement_norm_std": c.std,
                    "n": c.n,
                }
                for i, c in enumerate(self.per_load)
            ],
            "notes": list(self.notes),
        }


def _columns(ft, dt, ff: str, df: str, notes: list[str]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The force and displacement columns identified from: with rotations when the forces carry
    moments (all three, and the rotations then needed), else the forces and displacements."""
    f_mom = [c for c in FORCE_COLUMNS[3:] if ft.has(c)]
    d_rot = [c for c in DISP_COLUMNS[3:] if dt.has(c)]
    if f_mom and len(f_mom) < 3:
        missing = [c for c in FORCE_COLUMNS[3:] if c not in f_mom]
        raise InputError(f"has moment column(s) {', '.join(f_mom)} but not {', '.join(missing)}", source=ff)
    if f_mom:
        if len(d_rot) < 3:
            missing = [c for c in DISP_COLUMNS[3:] if c not in d_rot]
            raise InputError(
                f"missing column(s) {', '.join(repr(c) for c in missing)}: the forces carry moments "
                f"(mx, my, mz), so rotations are needed for a 6x6 stiffness",
                source=df,
            )
        return FORCE_COLUMNS, DISP_COLUMNS
    if d_rot:
        notes.append("rotations in the displacements are not used: the forces have no moments (3x3 K)")
    return FORCE_COLUMNS[:3], DISP_COLUMNS[:3]


def _repeat_groups(dt, D_all: np.ndarray, n_loads: int, ff: str, df: str) -> list[np.ndarray]:
    """The displacements of each repeat (the ``repeat`` column's labels in their order; one
    repeat without it), each one row per load case."""
    if "repeat" not in dt.text:
        if D_all.shape[1] != n_loads:
            raise InputError(
                f"has {D_all.shape[1]} data rows but {ff} has {n_loads} load cases; "
                "give one row per load case in the same order (or a 'repeat' column for repeats)",
                source=df,
            )
        return [D_all]
    labels = dt.text["repeat"]
    order: list[str] = []
    for lab in labels:
        if lab == "":
            raise InputError("column 'repeat' has an empty cell", source=df)
        if lab not in order:
            order.append(lab)
    groups = []
    for lab in order:
        rows = [i for i, x in enumerate(labels) if x == lab]
        if len(rows) != n_loads:
            raise InputError(
                f"repeat {lab!r} has {len(rows)} rows, expected {n_loads} (one per load case in {ff})",
                source=df,
            )
        groups.append(D_all[:, rows])
    return groups


def identify_from_files(
    forces_file: str | Path, displacements_file: str | Path, *, method: str = "compliance"
) -> IdentifyReport:
    """Read the two CSV files, check them against each other, identify K.

    Raises
    ------
    InputError
        For any problem with the files (missing, missing column, bad cell, a
        force or displacement beyond physical plausibility, row counts that do
        not match, too few independent loads, displacements that cannot give a
        finite stiffness), naming the file and the row or column.
    """
    ff, df = str(forces_file), str(displacements_file)
    ft = read_csv_columns(ff, FORCE_COLUMNS[:3], FORCE_COLUMNS[3:])
    ft.check_magnitude(FORCE_COLUMNS[:3], MAX_FORCE_N, "N", "force")
    ft.check_magnitude(FORCE_COLUMNS[3:], MAX_MOMENT_NMM, "N*mm", "moment")
    dt = read_csv_columns(df, DISP_COLUMNS[:3], DISP_COLUMNS[3:] + ("repeat",), text_columns=("repeat",))
    dt.check_magnitude(DISP_COLUMNS[:3], MAX_DISPLACEMENT_MM, "mm", "compliant displacement")
    dt.check_magnitude(DISP_COLUMNS[3:], MAX_ROTATION_RAD, "rad", "compliant rotation")
    notes: list[str] = []
    fcols, dcols = _columns(ft, dt, ff, df, notes)
    F1 = ft.stack(fcols)
    D_all = dt.stack(dcols)
    n_loads = F1.shape[1]
    groups = _repeat_groups(dt, D_all, n_loads, ff, df)
    if "repeat" in dt.text:
        D, F = np.concatenate(groups, axis=1), np.tile(F1, len(groups))
    else:
        D, F = D_all, F1
    repeats = len(groups)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StiffmapWarning)
        try:
            fit = identify_stiffness(F, D, method=method, names=(ff, df))
        except InputError as e:
            raise e.with_source(ff) from None
    for w in caught:
        if not issubclass(w.category, StiffmapWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    norms = np.stack([np.linalg.norm(g[:3], axis=0) for g in groups])  # (repeats, n_loads)
    per_load = [describe(norms[:, i]) for i in range(n_loads)]
    return IdentifyReport(fit=fit, forces=F1, repeats=repeats, per_load=per_load, notes=tuple(notes))
