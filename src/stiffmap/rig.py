"""Several calibrated cameras in one frame: the rig, and the ``rig.json`` file.

A :class:`Rig` is a list of named cameras (each a :class:`~stiffmap.camera.CameraModel`)
with the pose of each in the rig frame, ``cam2rig`` (mm). The first camera's frame is the
rig frame (its ``cam2rig`` is the identity), so a rig of one camera is that camera: a pose
in its rig frame is a pose in its camera frame.

Parameters and their covariance (``docs/conventions.md``, "Rigs"): the rig's calibrated
parameters are, camera after camera, the camera's own (:attr:`CameraModel.param_names`,
named ``"NAME.fx"``...) followed, for every camera but the first, by the perturbation of its
``cam2rig``: ``"NAME.tx"``, ``"NAME.ty"``, ``"NAME.tz"`` (mm, added to the translation, rig
frame) and ``"NAME.rx"``, ``"NAME.ry"``, ``"NAME.rz"`` (rad, a small rotation applied on the
left, R = Exp(r) R_hat, rig frame): the (t, r) perturbation of every pose in stiffmap
(:func:`~stiffmap.posemath.perturb_pose`). :attr:`Rig.calibration_cov` is the joint
covariance over them (a rig calibration's errors are correlated across cameras).

``rig.json``::

    {"cameras": [
        {"name": "left", "image_size": [w, h], "fx": ..., ..., "dist": [...],
         "cam2rig": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
        {"name": "right", ..., "cam2rig": [[...], ...]}],
     "cov": {"params": ["left.fx", ..., "right.rz"], "matrix": [[...], ...]},
     "dispersion": {"params": ["right.tx", ..., "right.rz"], "matrix": [[...], ...]},
     ...}

Each camera object holds every ``camera.json`` key (its own ``cov`` and ``std`` are its
intrinsics' marginal uncertainty) and ``cam2rig``; the top-level ``cov`` is the joint
covariance (optional: without it, the cameras' own covariances are taken as independent and
the poses between them as exact, :attr:`Rig.calibration_cov`). Other top-level keys (the
calibration's residuals and views) are kept as they are. :func:`load_rig` also reads a
``camera.json``: a rig of that one camera.

``dispersion`` (optional; older files have none): how much the cameras' poses relative to one
another scattered from one calibration view to the next beyond what the views' pose
covariances predict (:func:`~stiffmap.stats.excess_dispersion` over the per-view relative
poses, ``calibrate-rig``), a covariance over the ``cam2rig`` perturbations ``NAME.tx..rz``
(:attr:`Rig.dispersion`): a hand-held board moving between the cameras' exposures, what the
lens model leaves, correlated corner errors. It is not an error of the calibrated poses but
of each new view: the cameras' consistency test adds it (``vision.fuse``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .camera import CameraModel, check_cov_object, sigma_limits
from .errors import InputError
from .geometry import as_transform
from .io import dumps_json, read_json, replace_keeping_previous

__all__ = [
    "RigCamera",
    "Rig",
    "load_rig",
    "save_rig",
    "EXTRINSIC_NAMES",
    "CAMERA_FIELD",
    "MAX_RIG_MM",
    "camera_path",
    "parse_named_pattern",
]

#: The perturbation of a camera's ``cam2rig``: translation (mm) and left rotation (rad), rig frame.
EXTRINSIC_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")
#: How the name of an image set (one image per camera) holds the camera's name.
CAMERA_FIELD = "{camera}"


def camera_path(image_set: str, camera: str) -> str:
    """The file of ``camera`` in the image set ``image_set`` (a path holding ``{camera}``)."""
    return image_set.replace(CAMERA_FIELD, camera)


def parse_named_pattern(text: str) -> tuple[str, str]:
    """``NAME=GLOB`` (a camera's name and its images) -> ``(name, pattern)``, both stripped.

    The one parser of a camera's images given by name (``calibrate-rig --camera``,
    ``--images``, ``displacement --reference``).

    Raises
    ------
    ValueError
        Saying what is missing (the '=', the name, the images) or that the name holds
        characters that cannot be printed; the caller names the option or key.

    Examples
    --------
    >>> parse_named_pattern("left = img/left*.png")
    ('left', 'img/left*.png')
    """
    name, sep, pattern = str(text).partition("=")
    name, pattern = name.strip(), pattern.strip()
    if not sep:
        raise ValueError("expected NAME=GLOB, a camera's name and its images")
    if not name:
        raise ValueError("the camera's name before '=' is missing")
    if not name.isprintable():
        raise ValueError(f"the camera's name {name!r} holds characters that cannot be printed")
    if not pattern:
        raise ValueError("the images after '=' are missing")
    return name, pattern


#: Characters a camera's name may not hold: it is put into file names for ``{camera}``.
_NOT_IN_NAMES = ("/", "\\", "{", "}")
#: Tolerance on the first camera's ``cam2rig`` being the identity, and on rotations.
_IDENTITY_TOL = 1e-6
#: The farthest a camera of a rig may be from the first one, mm (100 m: a rig of cameras looking
#: at one robot; a translation beyond is a unit slip or a broken file, and reached the fusion's
#: linear algebra as an overflow).
MAX_RIG_MM = 1e5


@dataclass(frozen=True)
class RigCamera:
    """One camera of a rig.

    Attributes
    ----------
    name : str
        Its name (in file patterns ``{camera}``, campaign files and reports).
    camera : CameraModel
    cam2rig : ndarray, shape (4, 4), mm
        The camera's pose in the rig frame.
    """

    name: str
    camera: CameraModel
    cam2rig: np.ndarray

    def __post_init__(self) -> None:
        T = as_transform(self.cam2rig, f"{self.name}.cam2rig").copy()
        T.setflags(write=False)
        object.__setattr__(self, "cam2rig", T)


@dataclass(frozen=True)
class Rig:
    """Cameras in one frame (see the module docstring).

    Attributes
    ----------
    cameras : tuple of RigCamera
        The first one's frame is the rig frame.
    cov : ndarray, shape (n, n) or None
        Joint covariance over :attr:`param_names` (None: see :attr:`calibration_cov`).
    dispersion : ndarray, shape (n, n) or None
        The views' excess dispersion over :attr:`param_names` (non-zero in the ``cam2rig``
        perturbations only; see the module docstring); None: unknown (taken as zero).
    info : dict
        Other ``rig.json`` keys (residuals, views), kept as they came.
    """

    cameras: tuple[RigCamera, ...]
    cov: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    dispersion: np.ndarray | None = None

    def __post_init__(self) -> None:
        cams = tuple(self.cameras)
        object.__setattr__(self, "cameras", cams)
        if not cams:
            raise ValueError("a rig needs at least one camera")
        names = [c.name for c in cams]
        for n in names:
            if not isinstance(n, str) or not n.strip():
                raise ValueError(f"camera names must be non-empty strings, got {names!r}")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"camera names must differ, {dup[0]!r} is used twice")
        if np.abs(cams[0].cam2rig - np.eye(4)).max() > _IDENTITY_TOL:
            raise ValueError(
                f"the first camera ({cams[0].name}) is the rig frame: its cam2rig must be the identity"
            )
        if self.cov is not None:
            C = np.asarray(self.cov, dtype=np.float64)
            n = len(self.param_names)
            if C.shape != (n, n) or not np.all(np.isfinite(C)):
                raise ValueError(f"cov must be a finite ({n}, {n}) matrix over param_names, got {C.shape}")
            C = 0.5 * C + 0.5 * C.T  # (C + C.T) / 2 would overflow near 1e308
            C.setflags(write=False)
            object.__setattr__(self, "cov", C)
        if self.dispersion is not None:
            D = np.asarray(self.dispersion, dtype=np.float64)
            n = len(self.param_names)
            intrinsic = np.ones(n, dtype=bool)
            for k in range(1, len(cams)):
                intrinsic[self.extrinsic_slice(k)] = False
            if D.shape != (n, n) or not np.all(np.isfinite(D)):
                raise ValueError(
                    f"dispersion must be a finite ({n}, {n}) matrix over param_names, got {D.shape}"
                )
            if np.any(D[intrinsic]) or np.any(D[:, intrinsic]):
                raise ValueError("dispersion is over the cameras' cam2rig perturbations only (NAME.tx..rz)")
            D = 0.5 * D + 0.5 * D.T
            D.setflags(write=False)
            object.__setattr__(self, "dispersion", D)

    # ------------------------------------------------------------------ access
    @classmethod
    def single(cls, camera: CameraModel, name: str = "camera") -> Rig:
        """The rig of one camera (its frame is the rig frame)."""
        return cls((RigCamera(name, camera, np.eye(4)),))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cameras)

    def __len__(self) -> int:
        return len(self.cameras)

    def index(self, name: str) -> int:
        """Position of the camera called ``name`` (ValueError naming the rig's cameras)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"no camera {name!r} in the rig (cameras: {', '.join(self.names)})") from None

    def camera(self, name: str) -> CameraModel:
        return self.cameras[self.index(name)].camera

    # -------------------------------------------------------------- parameters
    @cached_property
    def param_names(self) -> tuple[str, ...]:
        """The rig's parameters, camera after camera (see the module docstring)."""
        out: list[str] = []
        for k, c in enumerate(self.cameras):
            out += [f"{c.name}.{p}" for p in c.camera.param_names]
            if k > 0:
                out += [f"{c.name}.{p}" for p in EXTRINSIC_NAMES]
        return tuple(out)

    def intrinsic_slice(self, k: int) -> slice:
        """Where camera ``k``'s own parameters are in :attr:`param_names`."""
        start = 0
        for j, c in enumerate(self.cameras):
            n = len(c.camera.param_names)
            if j == k:
                return slice(start, start + n)
            start += n + (6 if j > 0 else 0)
        raise IndexError(f"camera {k} out of range ({len(self)} cameras)")

    def extrinsic_slice(self, k: int) -> slice | None:
        """Where camera ``k``'s ``cam2rig`` perturbation is (None for the first camera)."""
        if k == 0:
            return None
        s = self.intrinsic_slice(k)
        return slice(s.stop, s.stop + 6)

    def sigma_limits(self) -> np.ndarray:
        """The largest plausible 1-sigma of each of :attr:`param_names`: the width of the range
        the parameter may take, the cameras' own (:func:`~stiffmap.camera.sigma_limits`), twice
        :data:`MAX_RIG_MM` for a ``cam2rig`` translation and 2 pi for its rotation."""
        out: list[float] = []
        for k, c in enumerate(self.cameras):
            out += list(sigma_limits(c.camera))
            if k > 0:
                out += [2 * MAX_RIG_MM] * 3 + [2 * math.pi] * 3
        return np.array(out)

    @cached_property
    def calibration_cov(self) -> np.ndarray | None:
        """Covariance of :attr:`param_names`, or None when no camera's uncertainty is known.

        ``cov`` when the rig has one; else the cameras' own calibration covariances
        (:attr:`CameraModel.calibration_cov`) as independent blocks, the ``cam2rig`` poses
        taken as exact (zero variance); None when no camera has one.
        """
        if self.cov is not None:
            return self.cov
        blocks = [c.camera.calibration_cov for c in self.cameras]
        if all(b is None for b in blocks):
            return None
        n = len(self.param_names)
        C = np.zeros((n, n))
        for k, b in enumerate(blocks):
            if b is not None:
                s = self.intrinsic_slice(k)
                C[s, s] = b
        C.setflags(write=False)  # computed once per rig (read for every pose of a campaign)
        return C

    @property
    def calibration_cov_source(self) -> str:
        """Where :attr:`calibration_cov` comes from: ``"cov"`` (the rig's joint covariance),
        ``"cameras"`` (the cameras' own, the poses in the rig exact) or ``"none"``."""
        if self.cov is not None:
            return "cov"
        return "cameras" if any(c.camera.calibration_cov is not None for c in self.cameras) else "none"

    # -------------------------------------------------------------------- json
    def to_dict(self) -> dict[str, Any]:
        """The ``rig.json`` object."""
        cams = []
        for c in self.cameras:
            d = {"name": c.name}
            d.update(c.camera.to_dict())
            d["cam2rig"] = c.cam2rig.tolist()
            cams.append(d)
        out: dict[str, Any] = {"cameras": cams}
        if self.cov is not None:
            out["cov"] = {"params": list(self.param_names), "matrix": self.cov.tolist()}
        if self.dispersion is not None:
            idx = [
                i for k in range(1, len(self)) for i in range(len(self.param_names))[self.extrinsic_slice(k)]
            ]
            out["dispersion"] = {
                "params": [self.param_names[i] for i in idx],
                "matrix": self.dispersion[np.ix_(idx, idx)].tolist(),
            }
        for k, v in self.info.items():
            if k not in out:
                out[k] = v
        return out

    @classmethod
    def from_dict(cls, data: Any, source: str = "rig.json") -> Rig:
        """Validate a ``rig.json`` object (or a ``camera.json`` one: a rig of that camera).

        Raises
        ------
        InputError
            Naming ``source`` and the key (``cameras[1].cam2rig``...) that is wrong.
        """
        if isinstance(data, dict) and "cameras" not in data and "fx" in data:
            return cls.single(CameraModel.from_dict(data, source=source))
        if not isinstance(data, dict) or "cameras" not in data:
            raise InputError(
                "expected a JSON object with the key 'cameras' (a list of cameras with a 'name', "
                "the camera.json keys and 'cam2rig'), or a camera.json object",
                source=source,
            )

        def bad(key: str, what: str) -> InputError:
            return InputError(f"key {key!r}: {what}", source=source)

        items = data["cameras"]
        if not isinstance(items, list) or not items:
            raise bad("cameras", "must be a non-empty list of camera objects")
        cams: list[RigCamera] = []
        seen: set[str] = set()
        for i, item in enumerate(items):
            key = f"cameras[{i}]"
            if not isinstance(item, dict):
                raise bad(key, f"must be an object, got {type(item).__name__}")
            name = item.get("name")
            if not isinstance(name, str) or not name.strip() or name != name.strip():
                raise bad(f"{key}.name", f"must be a non-empty name without outer spaces, got {name!r}")
            if not name.isprintable() or any(c in name for c in _NOT_IN_NAMES):
                raise bad(
                    f"{key}.name",
                    f"{name!r} cannot name a camera's image files (it stands for {CAMERA_FIELD} in "
                    "their names: no / \\ { } or unprintable characters)",
                )
            if name in seen:
                raise bad(f"{key}.name", f"{name!r} is the name of an earlier camera: names must differ")
            seen.add(name)
            if "cam2rig" not in item:
                if i == 0:
                    T = np.eye(4)
                else:
                    raise bad(f"{key}.cam2rig", "missing (the camera's pose in the rig frame, 4x4, mm)")
            else:
                T = _transform(item["cam2rig"], f"{key}.cam2rig", bad)
            if i == 0 and np.abs(T - np.eye(4)).max() > _IDENTITY_TOL:
                raise bad(f"{key}.cam2rig", "the first camera's frame is the rig frame: must be the identity")
            body = {k: v for k, v in item.items() if k not in ("name", "cam2rig")}
            camera = CameraModel.from_dict(body, source=f"{source}: {key} ({name})")
            cams.append(RigCamera(name, camera, T))
        rig = cls(tuple(cams))
        cov = None
        if data.get("cov") is not None:
            cov = check_cov_object(data["cov"], rig.param_names, bad, of="this rig")
            _check_sigmas(rig, cov, bad)
        dispersion = _dispersion(rig, data.get("dispersion"), bad)
        info = {k: v for k, v in data.items() if k not in ("cameras", "cov", "dispersion")}
        return cls(rig.cameras, cov=cov, info=info, dispersion=dispersion)


def _dispersion(rig: Rig, value: Any, bad) -> np.ndarray | None:
    """The ``dispersion`` object over the cameras' ``cam2rig`` perturbations (None when absent)."""
    if value is None:
        return None
    names = tuple(f"{c.name}.{p}" for c in rig.cameras[1:] for p in EXTRINSIC_NAMES)
    if not names:
        raise bad("dispersion", "a rig of one camera has no poses between cameras to disperse")
    # check_cov_object names its keys "cov", "cov.params", "cov.matrix": here they are dispersion's.
    D = check_cov_object(
        value,
        names,
        lambda key, what: bad(key.replace("cov", "dispersion", 1), what),
        of="the cameras' poses",
    )
    full = np.zeros((len(rig.param_names),) * 2)
    idx = [rig.param_names.index(n) for n in names]
    full[np.ix_(idx, idx)] = D
    return full


def _check_sigmas(rig: Rig, cov: np.ndarray, bad) -> None:
    """InputError at the first parameter whose 1-sigma in ``cov`` is beyond :meth:`Rig.sigma_limits`."""
    s = np.sqrt(np.abs(np.diag(cov)))
    limits = rig.sigma_limits()
    over = np.flatnonzero(~(s <= limits))
    if over.size:
        k = int(over[0])
        raise bad(
            "cov.matrix",
            f"a 1-sigma of {s[k]:.3g} for {rig.param_names[k]} is not a calibration's uncertainty (at "
            f"most {limits[k]:.3g}; a variance where a standard deviation belongs, or another unit?)",
        )


def _transform(v: Any, key: str, bad) -> np.ndarray:
    if (
        not isinstance(v, list)
        or len(v) != 4
        or not all(isinstance(r, list) and len(r) == 4 for r in v)
        or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for r in v for x in r
        )
    ):
        raise bad(key, "must be a 4x4 list of finite numbers (a rigid transform, mm)")
    T = np.array(v, dtype=np.float64)
    far = float(np.abs(T[:3, 3]).max())
    if far > MAX_RIG_MM:
        raise bad(
            key,
            f"a camera {far:.3g} mm from the first one: not a rig (at most {MAX_RIG_MM:g} mm, 100 m; "
            "a translation in um, or a broken file?)",
        )
    try:
        return as_transform(T, key)
    except ValueError as e:
        raise bad(key, str(e).split(": ", 1)[-1]) from None


def load_rig(path: str | Path) -> Rig:
    """Read and validate a ``rig.json`` (or a ``camera.json``: a rig of one camera)."""
    return Rig.from_dict(read_json(path, "rig file"), source=str(path))


def save_rig(rig: Rig, path: str | Path) -> Path | None:
    """Write ``rig.json`` atomically; a different earlier file is kept as ``rig.json.bak``."""
    return replace_keeping_previous(path, dumps_json(rig.to_dict()) + "\n")
