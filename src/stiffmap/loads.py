"""Load cases: forces from calibrated masses, friction correction, presets.

Masses in kg become forces in N here, once, with the campaign's g (default
9.80665 m/s^2; the reference vision study used 9.81). Directions are unit
vectors in the robot base frame.

Friction correction: the reference study applied X and Y loads through a
pulley; the force reaching the platform is the weight minus a friction force
measured with a dynamometer (28 g +- 8 g on a 500 g load, 10 repeats). The
applied force is ``nominal - friction`` along the load direction, and the
friction's standard deviation becomes the force's uncertainty along that
direction.

A load design -- the load cases applied at every position -- is a preset's name
or a CSV file of forces (:func:`load_design`, :func:`read_loads_csv`);
:func:`check_load_design` refuses one whose forces cannot determine a 3x3
stiffness (fewer than three independent directions).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DesignError, InputError
from .io import read_csv_columns
from .units import G_REFERENCE_PAPER, G_STANDARD

__all__ = [
    "LoadCase",
    "load_from_mass",
    "with_friction",
    "forces_matrix",
    "force_covariances",
    "paper9",
    "PRESETS",
    "preset",
    "scaled_loads",
    "AXES",
    "check_load_design",
    "read_loads_csv",
    "load_design",
    "MAX_FORCE_N",
    "MAX_MOMENT_NMM",
]

#: Largest force a load file may hold, N (1e5 tonnes-force: beyond, the file is broken or
#: not in N). A plausibility limit at the input boundary, far above any stiffness test.
MAX_FORCE_N = 1e9
#: Largest moment a load file may hold, N*mm (1e9 N at 1 m).
MAX_MOMENT_NMM = 1e12

#: Named directions in the base frame.
AXES: dict[str, tuple[float, float, float]] = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}


def _direction(direction) -> np.ndarray:
    if isinstance(direction, str):
        key = direction.strip().lower()
        key = key if key[0] in "+-" else "+" + key
        if key not in AXES:
            raise ValueError(
                f"unknown direction {direction!r}; expected one of x, y, z, -x, -y, -z or a vector"
            )
        return np.array(AXES[key])
    u = np.asarray(direction, dtype=np.float64)
    if u.shape != (3,) or not np.all(np.isfinite(u)):
        raise ValueError(f"direction must be a finite 3-vector, got {direction!r}")
    n = np.linalg.norm(u)
    if n == 0:
        raise ValueError("direction must be non-zero")
    return u / n


@dataclass(frozen=True)
class LoadCase:
    """One load case: a force (N) in the base frame, with its covariance.

    Attributes
    ----------
    force : ndarray, shape (3,)
        Applied force, N.
    cov : ndarray, shape (3, 3)
        Covariance of the applied force, N^2 (zero for an exact load).
    label : str
        Human-readable name, e.g. ``"0.5 kg -y"``.
    """

    force: np.ndarray
    cov: np.ndarray
    label: str = ""

    def __post_init__(self) -> None:
        f = np.asarray(self.force, dtype=np.float64)
        c = np.asarray(self.cov, dtype=np.float64)
        if f.shape != (3,) or not np.all(np.isfinite(f)):
            raise ValueError(f"force must be a finite 3-vector in N, got {self.force!r}")
        if c.shape != (3, 3) or not np.all(np.isfinite(c)):
            raise ValueError(f"cov must be a finite 3x3 matrix in N^2, got shape {c.shape}")
        f.setflags(write=False)
        c.setflags(write=False)
        object.__setattr__(self, "force", f)
        object.__setattr__(self, "cov", c)

    @property
    def magnitude(self) -> float:
        """|force|, N."""
        return float(np.linalg.norm(self.force))


def load_from_mass(mass_kg: float, direction, *, g: float = G_STANDARD, label: str | None = None) -> LoadCase:
    """Load case of a hanging mass.

    Parameters
    ----------
    mass_kg : float
        Mass, kg (> 0).
    direction : str or array_like, shape (3,)
        ``"x"``, ``"-z"``... or a vector in the base frame (normalised).
    g : float
        Gravity, m/s^2.
    """
    if not (np.isfinite(mass_kg) and mass_kg > 0):
        raise ValueError(f"mass must be a positive number of kg, got {mass_kg!r}")
    if not (np.isfinite(g) and g > 0):
        raise ValueError(f"g must be a positive number of m/s^2, got {g!r}")
    u = _direction(direction)
    name = label if label is not None else f"{mass_kg:g} kg {_dir_name(u)}"
    return LoadCase(mass_kg * g * u, np.zeros((3, 3)), name)


def _dir_name(u: np.ndarray) -> str:
    for k, v in AXES.items():
        if np.allclose(u, v):
            return k
    return "(" + ", ".join(f"{x:.3g}" for x in u) + ")"


def with_friction(
    load: LoadCase, friction_kg: float, friction_std_kg: float = 0.0, *, g: float = G_STANDARD
) -> LoadCase:
    """Subtract a measured friction force along the load's direction.

    Parameters
    ----------
    load : LoadCase
    friction_kg, friction_std_kg : float
        Mean and standard deviation of the friction, as a mass (kg), measured
        with a dynamometer (the reference study: 0.028 and 0.008 kg for 0.5 kg).
    g : float
        Gravity, m/s^2.

    Returns
    -------
    LoadCase
        Force (|F| - friction g) along the same direction; covariance
        increased by (friction_std g)^2 along it.
    """
    if not (np.isfinite(friction_kg) and friction_kg >= 0):
        raise ValueError(f"friction must be a non-negative mass in kg, got {friction_kg!r}")
    if not (np.isfinite(friction_std_kg) and friction_std_kg >= 0):
        raise ValueError(f"friction standard deviation must be >= 0 kg, got {friction_std_kg!r}")
    mag = load.magnitude
    if mag == 0:
        raise ValueError("cannot correct a zero load for friction")
    fr = friction_kg * g
    if fr >= mag:
        raise ValueError(f"friction ({fr:.4g} N) is not smaller than the load ({mag:.4g} N)")
    u = load.force / mag
    cov = load.cov + (friction_std_kg * g) ** 2 * np.outer(u, u)
    return LoadCase(load.force - fr * u, cov, f"{load.label} - friction")


def forces_matrix(loads: Sequence[LoadCase]) -> np.ndarray:
    """Forces of load cases as columns, shape (3, n), N."""
    return np.stack([ld.force for ld in loads], axis=1)


def force_covariances(loads: Sequence[LoadCase]) -> np.ndarray:
    """Force covariances of load cases, shape (n, 3, 3), N^2."""
    return np.stack([ld.cov for ld in loads])


def paper9(*, g: float = G_REFERENCE_PAPER) -> list[LoadCase]:
    """The reference vision study's nine load cases (its Table II).

    0.5, 0.2 and 0.1 kg along +y, -x and -z, in that order; with its g = 9.81
    the forces are (0, 4.905, 0), (-4.905, 0, 0), (0, 0, -4.905), (0, 1.962, 0),
    (-1.962, 0, 0), (0, 0, -1.962), (0, 0.981, 0), (-0.981, 0, 0), (0, 0, -0.981) N.
    """
    out = []
    for m in (0.5, 0.2, 0.1):
        for d in ("+y", "-x", "-z"):
            out.append(load_from_mass(m, d, g=g))
    return out


#: Named load designs.
PRESETS = {"paper9": paper9}


def preset(name: str, *, g: float | None = None) -> list[LoadCase]:
    """A named load design (``paper9``)."""
    if name not in PRESETS:
        raise ValueError(f"unknown load preset {name!r}; known: {', '.join(PRESETS)}")
    return PRESETS[name]() if g is None else PRESETS[name](g=g)


def scaled_loads(loads: Sequence[LoadCase], factor: float) -> list[LoadCase]:
    """The load cases ``factor`` times heavier: forces times ``factor``, covariances times its
    square, a mass in a label (``0.5 kg +y``) times ``factor`` (else `` x factor`` appended).

    Examples
    --------
    >>> [ld.label for ld in scaled_loads(paper9()[:2], 50)]
    ['25 kg +y', '25 kg -x']
    """
    f = float(factor)
    if not (np.isfinite(f) and f > 0):
        raise ValueError(f"factor must be a positive number, got {factor!r}")
    out = []
    for ld in loads:
        m = _MASS_LABEL.match(ld.label)
        label = f"{float(m.group(1)) * f:g} kg{m.group(2)}" if m else f"{ld.label} x {f:g}".strip()
        out.append(LoadCase(np.asarray(ld.force) * f, np.asarray(ld.cov) * f * f, label))
    return out


_MASS_LABEL = re.compile(r"^\s*([0-9.]+(?:e[-+]?[0-9]+)?) kg(.*)$")


def check_load_design(forces, *, source: str | None = None) -> None:
    """Refuse forces that cannot determine a 3x3 stiffness.

    Parameters
    ----------
    forces : array_like, shape (n, 3), N
        One force per row (not all zero).
    source : str, optional
        The file the forces come from, named in the message.

    Raises
    ------
    ValueError
        When ``forces`` is not a non-empty (n, 3) array of finite numbers.
    DesignError
        When the forces span fewer than three independent directions (the rank
        found is in the message; rank tolerance 1e-9 of the largest component).
    """
    F = np.asarray(forces, dtype=np.float64)
    if F.ndim != 2 or F.shape[0] == 0 or F.shape[1] != 3 or not np.all(np.isfinite(F)):
        raise ValueError(f"forces must be a non-empty (n, 3) array of finite N, got shape {F.shape}")
    rank = int(np.linalg.matrix_rank(F, tol=1e-9 * float(np.abs(F).max())))
    if rank < 3:
        raise DesignError(
            f"the {len(F)} load(s) span {rank} independent direction(s); 3 are needed to identify "
            "a 3x3 stiffness (add loads along other axes)",
            source=source,
        )


def read_loads_csv(path: str | os.PathLike) -> list[LoadCase]:
    """Load cases from a CSV file with columns fx, fy, fz (N) and optionally label.

    An empty or missing label becomes ``F = (fx, fy, fz) N``. The design is checked
    (:func:`check_load_design`).

    Raises
    ------
    InputError
        Naming the file (and the line of a zero force), a missing column or a bad
        cell; :class:`~stiffmap.errors.DesignError` when the forces span fewer than
        three directions.
    """
    src = str(path)
    t = read_csv_columns(path, ("fx", "fy", "fz"), ("label",), text_columns=("label",))
    t.check_magnitude(("fx", "fy", "fz"), MAX_FORCE_N, "N", "force")
    F = t.stack(("fx", "fy", "fz")).T
    labels = t.text.get("label", [""] * len(F))
    cases = []
    for i, (f, lab) in enumerate(zip(F, labels, strict=True)):
        if not np.any(f):
            raise InputError(f"line {t.lines[i]}: the force is zero", source=src)
        cases.append(LoadCase(f, np.zeros((3, 3)), lab or f"F = ({', '.join(f'{v:g}' for v in f)}) N"))
    check_load_design(F, source=src)
    return cases


def load_design(text: str, g: float | None = None) -> list[LoadCase]:
    """The load cases a user names: a preset (``PRESETS``, any case) or a CSV file (:func:`read_loads_csv`).

    Parameters
    ----------
    text : str
        ``paper9`` or the path of a CSV file.
    g : float, optional
        Gravity for a preset's masses, m/s^2 (default: the preset's own).

    Raises
    ------
    ValueError
        As ``'text': expected a preset (paper9) or a CSV file ...`` when ``text`` is
        neither (the command line puts the option's name in front).
    InputError
        From :func:`read_loads_csv`, naming the file.
    """
    key = text.strip().lower()
    if key in PRESETS:
        return preset(key, g=g)
    if not Path(text).is_file():
        raise ValueError(
            f"{text!r}: expected a preset ({', '.join(PRESETS)}) or a CSV file with columns "
            "fx, fy, fz (N) and optionally label"
        )
    return read_loads_csv(text)
