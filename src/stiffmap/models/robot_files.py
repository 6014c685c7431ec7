"""Robot description files: URDF (plain or xacro) read into its kinematic tree, as data.

The one place that opens a robot description for the URDF models (``docs/models.md``,
"Robot descriptions as published"). :func:`read_urdf` reads a file -- expanding a
``.xacro`` one first (:func:`expand_xacro`) -- and :func:`parse_urdf` turns its text into a
:class:`UrdfTree`: the links and the joints *directly under* ``<robot>``, each joint with
its type, parent and child links, origin, axis, limits and ``<mimic>``. Everything else a
published description carries is ignored: ``<transmission>`` and ``<ros2_control>`` blocks
(whose own ``<joint>`` elements have no type), ``<gazebo>``, sensors, materials, inertias,
visual and collision geometry (meshes and ``package://`` URIs are never opened).

A joint's own problems (an unknown type, an origin that is not three finite numbers, a
mimic without its leader's name) are kept in :attr:`UrdfJoint.problem`: they matter only
when the joint lies on the chain a model uses, which :mod:`~stiffmap.models.chain` decides.
The tree itself must hold: every joint has a name, a parent and a child link the file
defines, no link is the child of two joints, no joint name is used twice.

xacro. A ``.xacro`` file is expanded by the ``xacro`` package (PyPI; the ROS tool without
ROS), with ``xacro:arg`` values given as ``NAME=VALUE`` and ``$(find PKG)`` resolved from
the package folders given (``--package-path``), ``ROS_PACKAGE_PATH``, then the workspace
the file lies in (the folder holding its own package: its siblings): a folder named PKG,
or holding a ``package.xml`` whose ``<name>`` is PKG, at most four levels below one of
them; ``<xacro:include filename="package://PKG/...">`` likewise. A package only named in
text (a Gazebo plugin's parameters) need not be found; an unresolved package needed to
include or load a file, or an argument without value, is one
:class:`~stiffmap.errors.InputError` naming it. Units stay the file's: metres and radians
(the chain turns them into mm).
"""

from __future__ import annotations

import contextlib
import io as _io
import math
import os
import re
import threading
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import xacro
import xacro.substitution_args as xacro_subs

from ..errors import InputError
from ..io import parse_number, read_text_file
from .links import Beam, LinkSpring, check_beam, check_compliance_matrix

__all__ = [
    "UrdfJoint",
    "UrdfMimic",
    "UrdfTree",
    "MOVING_TYPES",
    "URDF_JOINT_TYPES",
    "MAX_ORIGIN_M",
    "MAX_MIMIC_MULTIPLIER",
    "parse_urdf",
    "read_urdf",
    "expand_xacro",
    "is_xacro",
    "find_package",
    "package_search_path",
    "own_workspace",
    "read_links_toml",
    "links_from_tables",
]

#: Joint types that move (one coordinate each; "continuous" is an unlimited revolute joint).
MOVING_TYPES = ("revolute", "continuous", "prismatic")
#: Every joint type of the URDF format.
URDF_JOINT_TYPES = (*MOVING_TYPES, "fixed", "floating", "planar")
#: Largest origin coordinate taken (m): 1000 km; beyond, a description is not a robot's.
MAX_ORIGIN_M = 1e6
#: Largest ``<mimic multiplier>`` taken (a gear ratio, in m/rad between a prismatic and a
#: revolute joint); beyond, the follower's motion overflows the Jacobian.
MAX_MIMIC_MULTIPLIER = 1e6
#: How deep below a package folder ``$(find PKG)`` looks for ``PKG``.
PACKAGE_SEARCH_DEPTH = 4

_XACRO_LOCK = threading.Lock()


@dataclass(frozen=True)
class UrdfMimic:
    """A ``<mimic>``: the joint's coordinate is ``multiplier * q(joint) + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` directly under ``<robot>``, in the file's units (m, rad).

    Attributes
    ----------
    name, type, parent, child : str
    xyz : tuple of 3 floats, m
        ``<origin xyz>``: the joint frame's origin in the parent link's frame.
    rpy : tuple of 3 floats, rad
        ``<origin rpy>``: its orientation (roll about x, pitch about y, yaw about z, fixed axes).
    axis : tuple of 3 floats
        ``<axis xyz>`` in the joint frame (default (1, 0, 0), the URDF default).
    lower, upper : float
        ``<limit lower upper>`` (rad, or m for a prismatic joint); -inf/inf for a continuous
        joint or a moving joint without ``<limit>``.
    mimic : UrdfMimic or None
    problem : str
        What is wrong with this joint's own elements ("" when nothing): it matters only
        when the joint is on a model's chain.
    """

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    lower: float = -math.inf
    upper: float = math.inf
    mimic: UrdfMimic | None = None
    problem: str = ""


@dataclass(frozen=True)
class UrdfTree:
    """The kinematic tree of a URDF: its links and joints, nothing else.

    Attributes
    ----------
    name : str
        ``<robot name>``.
    source : str
        The file (for messages).
    links : tuple of str
        Link names, in the file's order.
    joints : dict of str to UrdfJoint
        By name, in the file's order.
    parent_joint : dict of str to str
        For each link that is a child, the joint above it.
    text : str
        The URDF it was read from (a xacro file's expansion): what a simulated campaign's
        folder gets, so that it needs neither xacro nor the packages.
    """

    name: str
    source: str
    links: tuple[str, ...]
    joints: dict[str, UrdfJoint]
    parent_joint: dict[str, str] = field(default_factory=dict)
    text: str = field(default="", repr=False)

    @property
    def roots(self) -> tuple[str, ...]:
        """Links that are no joint's child (a URDF has one; a file of two robots, more)."""
        return tuple(lk for lk in self.links if lk not in self.parent_joint)

    def path_to(self, link: str) -> list[str]:
        """The joints from the root of ``link``'s tree down to ``link`` (root first)."""
        out: list[str] = []
        seen: set[str] = set()
        at = link
        while at in self.parent_joint:
            j = self.parent_joint[at]
            if j in seen:  # cannot happen once parse_urdf has checked the tree; kept as a guard
                raise InputError(
                    f"the joints above link {link!r} form a loop through {j!r}", source=self.source
                )
            seen.add(j)
            out.append(j)
            at = self.joints[j].parent
        return out[::-1]


def _floats(text: str | None, n: int, default: tuple[float, ...]) -> tuple[float, ...] | None:
    """n finite numbers from an attribute (its default when absent); None when malformed."""
    if text is None:
        return default
    parts = text.replace(",", " ").split()
    if len(parts) != n:
        return None
    try:
        vals = tuple(parse_number(p) for p in parts)
    except ValueError:
        return None
    return vals if all(math.isfinite(v) for v in vals) else None


def _number(text: str | None, default: float) -> float | None:
    if text is None:
        return default
    try:
        v = parse_number(text)
    except ValueError:
        return None
    return v if not math.isnan(v) else None


def _joint(el: ET.Element, index: int, source: str) -> UrdfJoint:
    """A ``<joint>`` element as data; structural faults raise, local ones go to ``problem``."""
    name = el.get("name")
    if not name:
        raise InputError(f"not a URDF: <joint> number {index} under <robot> has no name", source=source)
    par, chi = el.find("parent"), el.find("child")
    parent = par.get("link") if par is not None else None
    child = chi.get("link") if chi is not None else None
    if not parent or not child:
        which = "<parent link=...>" if not parent else "<child link=...>"
        raise InputError(f"not a URDF: joint {name!r} has no {which}", source=source)
    jtype = el.get("type", "")
    problems = []
    if jtype not in URDF_JOINT_TYPES:
        problems.append(f"is of type {jtype!r} (URDF joints are {', '.join(URDF_JOINT_TYPES)})")
    origin = el.find("origin")
    xyz = _floats(origin.get("xyz") if origin is not None else None, 3, (0.0, 0.0, 0.0))
    rpy = _floats(origin.get("rpy") if origin is not None else None, 3, (0.0, 0.0, 0.0))
    if xyz is None or rpy is None:
        what = "xyz" if xyz is None else "rpy"
        problems.append(f"<origin {what}> is not three finite numbers")
    elif max(abs(v) for v in xyz) > MAX_ORIGIN_M:
        problems.append(f"<origin xyz> {' '.join(f'{v:g}' for v in xyz)} m is beyond {MAX_ORIGIN_M:g} m")
    ax_el = el.find("axis")
    axis = _floats(ax_el.get("xyz") if ax_el is not None else None, 3, (1.0, 0.0, 0.0))
    if axis is None or (jtype in MOVING_TYPES and math.hypot(*axis) == 0):
        problems.append("<axis xyz> is not three finite numbers, not all zero")
    lower, upper = -math.inf, math.inf
    lim = el.find("limit")
    if lim is not None and jtype in ("revolute", "prismatic"):
        lo, hi = _number(lim.get("lower"), 0.0), _number(lim.get("upper"), 0.0)
        if lo is None or hi is None or lo > hi:
            problems.append(f"<limit lower={lim.get('lower')!r} upper={lim.get('upper')!r}> is not a range")
        else:
            lower, upper = lo, hi
    mimic = None
    mel = el.find("mimic")
    if mel is not None and jtype in MOVING_TYPES:
        leader = mel.get("joint")
        mult, off = _number(mel.get("multiplier"), 1.0), _number(mel.get("offset"), 0.0)
        if not leader:
            problems.append("<mimic> names no joint")
        elif mult is None or off is None or not (math.isfinite(mult) and math.isfinite(off)):
            problems.append("<mimic multiplier/offset> is not a finite number")
        elif abs(mult) > MAX_MIMIC_MULTIPLIER:
            problems.append(f"<mimic multiplier> {mult:g} is beyond +-{MAX_MIMIC_MULTIPLIER:g}")
        elif abs(off) > MAX_ORIGIN_M:
            problems.append(f"<mimic offset> {off:g} is beyond +-{MAX_ORIGIN_M:g} (m or rad)")
        else:
            mimic = UrdfMimic(leader, mult, off)
    return UrdfJoint(
        name,
        jtype,
        parent,
        child,
        xyz or (0.0, 0.0, 0.0),
        rpy or (0.0, 0.0, 0.0),
        axis or (1.0, 0.0, 0.0),
        lower,
        upper,
        mimic,
        "; ".join(problems),
    )


def parse_urdf(text: str, source: str = "URDF") -> UrdfTree:
    """The kinematic tree of a URDF's text (``<link>`` and ``<joint>`` directly under ``<robot>``).

    Parameters
    ----------
    text : str
        The URDF (XML).
    source : str
        Its file, for messages.

    Returns
    -------
    UrdfTree

    Raises
    ------
    InputError
        Naming ``source``: not XML, not ``<robot>``, a joint without name, parent or child,
        a link named by a joint but not defined, a link with two parent joints, a joint
        name used twice, joints forming a loop.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise InputError(f"not a valid XML file ({e})", source=source) from None
    for el in root.iter():  # a default namespace (xacro:targetNamespace) is not part of the names
        if isinstance(el.tag, str) and el.tag.startswith("{"):
            el.tag = el.tag.split("}", 1)[1]
    if root.tag != "robot":
        raise InputError(f"not a URDF: the root element is <{root.tag}>, expected <robot>", source=source)
    links = tuple(el.get("name") or "" for el in root.findall("link"))
    if "" in links:
        raise InputError("not a URDF: a <link> has no name", source=source)
    if len(set(links)) != len(links):
        twice = next(lk for lk in links if links.count(lk) > 1)
        raise InputError(f"not a URDF: two links are named {twice!r}", source=source)
    known = set(links)
    joints: dict[str, UrdfJoint] = {}
    parent_joint: dict[str, str] = {}
    for i, el in enumerate(root.findall("joint"), start=1):
        j = _joint(el, i, source)
        if j.name in joints:
            raise InputError(f"not a URDF: two joints are named {j.name!r}", source=source)
        for role, lk in (("parent", j.parent), ("child", j.child)):
            if lk not in known:
                raise InputError(
                    f"joint {j.name!r} names {role} link {lk!r}, which the file does not define",
                    source=source,
                )
        if j.child in parent_joint:
            raise InputError(
                f"not a URDF: link {j.child!r} is the child of two joints ({parent_joint[j.child]!r} and "
                f"{j.name!r}); a URDF is a tree",
                source=source,
            )
        joints[j.name] = j
        parent_joint[j.child] = j.name
    tree = UrdfTree(root.get("name") or "robot", source, links, joints, parent_joint, text)
    for lk in links:  # a loop has no root: walking up from any of its links never ends
        at, seen = lk, set()
        while at in parent_joint:
            if at in seen:
                raise InputError(f"not a URDF: the joints above link {lk!r} form a loop", source=source)
            seen.add(at)
            at = joints[parent_joint[at]].parent
    return tree


def is_xacro(path: str | os.PathLike) -> bool:
    """Whether a file is taken as xacro: its name ends in ``.xacro`` (``robot.urdf.xacro`` too)."""
    return str(path).lower().endswith(".xacro")


def package_search_path(package_paths: Sequence[str | os.PathLike] = ()) -> list[Path]:
    """The folders ``$(find PKG)`` searches: ``package_paths``, then ``ROS_PACKAGE_PATH``'s."""
    env = os.environ.get("ROS_PACKAGE_PATH", "")
    return [Path(p) for p in package_paths] + [Path(p) for p in env.split(os.pathsep) if p]


def own_workspace(path: str | os.PathLike) -> list[Path]:
    """The folder holding the package a file lies in (its nearest folder with a ``package.xml``):
    where the file's own package and its siblings are, as a ROS workspace's source folder holds
    them; empty when no folder above the file is a package."""
    for d in Path(path).resolve().parents:
        if (d / "package.xml").is_file():
            return [d.parent]
    return []


def _package_name(folder: Path) -> str | None:
    """The ``<name>`` of ``folder/package.xml``, or None."""
    f = folder / "package.xml"
    if not f.is_file():
        return None
    try:
        el = ET.parse(f).getroot().find("name")
    except (ET.ParseError, OSError):
        return None
    return el.text.strip() if el is not None and el.text else None


def find_package(name: str, search: Sequence[Path]) -> Path | None:
    """The folder of ROS package ``name`` under the ``search`` folders, or None.

    A folder is the package when its ``package.xml`` names it, or (a description copied
    without its ``package.xml``) when it is named so; each search folder is looked at itself
    and down to :data:`PACKAGE_SEARCH_DEPTH` levels, the first match in search order wins.
    """
    for top in search:
        if not top.is_dir():
            continue
        level = [top]
        for _ in range(PACKAGE_SEARCH_DEPTH + 1):
            nxt = []
            for d in level:
                pkg = _package_name(d)
                if pkg == name or (pkg is None and d.name == name):
                    return d
                if pkg is None:  # a package does not hold others
                    with contextlib.suppress(OSError):
                        nxt.extend(
                            sorted(c for c in d.iterdir() if c.is_dir() and not c.name.startswith("."))
                        )
            level = nxt
    return None


#: Where an unresolved ``$(find PKG)`` points (no file is there): a package only named in text
#: (a Gazebo plugin's parameters, a mesh) is not needed for the kinematic tree, so expansion
#: goes on; one needed to include or load a file fails there, and is named then.
_UNRESOLVED = "/stiffmap-unresolved-package"
#: That path in the expanded text, given back as the ``$(find PKG)`` it was (the expansion
#: copied into a simulated campaign's folder keeps no path of stiffmap's).
_UNRESOLVED_IN_TEXT = re.compile(rf"{re.escape(_UNRESOLVED)}/([^/\s\"'<>]+)")


def expand_xacro(
    path: str | os.PathLike,
    args: Mapping[str, str] | None = None,
    package_paths: Sequence[str | os.PathLike] = (),
) -> str:
    """The URDF text a xacro file expands to.

    Parameters
    ----------
    path : path-like
        The ``.xacro`` file.
    args : mapping of str to str, optional
        ``xacro:arg`` values (``--xacro-arg NAME=VALUE``).
    package_paths : sequence of path-like
        Folders holding ROS packages, searched for ``$(find PKG)`` before ``ROS_PACKAGE_PATH``
        and the file's own workspace (:func:`own_workspace`).

    Returns
    -------
    str
        The expanded XML.

    Raises
    ------
    InputError
        Naming the file: a package no folder holds (the folders searched are listed), an
        argument without value, or xacro's own message (a missing include, a macro error).
    """
    src = str(path)
    search = package_search_path(package_paths) + own_workspace(path)

    def find(pkg: str) -> str:
        d = find_package(pkg, search)
        return f"{_UNRESOLVED}/{pkg}" if d is None else str(d.resolve())

    p = Path(path)
    if not p.is_file():
        raise InputError("cannot read: no such file" if not p.exists() else "is not a file", source=src)
    err = _io.StringIO()
    with _XACRO_LOCK, contextlib.redirect_stderr(err), contextlib.redirect_stdout(err):
        saved = xacro_subs._eval_find, xacro_subs._eval_dict.get("find")
        xacro_subs._eval_find = find  # xacro finds packages through ament; here from the folders given
        xacro_subs._eval_dict["find"] = find
        parse = xacro.parse
        xacro.parse = _legacy_tags(parse)
        try:
            doc = xacro.process_file(str(p.resolve()), mappings=dict(args or {}))
            return _UNRESOLVED_IN_TEXT.sub(r"$(find \1)", doc.toxml())  # kept as written
        except Exception as e:  # noqa: BLE001  xacro raises many kinds; each becomes one line
            text = _chain_text(e)
            if f"{_UNRESOLVED}/" in text:
                pkg = text.split(f"{_UNRESOLVED}/", 1)[1].split("/", 1)[0].split()[0].strip("'\"")
                where = ", ".join(str(s) for s in search) or "none given"
                raise InputError(
                    f"xacro: $(find {pkg}): no package {pkg!r} in the package folders ({where}); give its "
                    "folder with --package-path DIR (campaign.toml: package_paths) or ROS_PACKAGE_PATH",
                    source=src,
                ) from None
            where = "" if _cause(e, "ArgException") else _xacro_where(p)  # arguments are global
            hint = _default_arg_hint(p, text) if "No such file" in text else ""
            raise InputError(f"xacro: {_xacro_message(e)}{hint}{where}", source=src) from None
        finally:
            xacro.parse = parse
            xacro_subs._eval_find, xacro_subs._eval_dict["find"] = saved
            xacro.init_stacks(None)


#: ROS 1's xacro also took these tags without the ``xacro:`` prefix (older ROS-Industrial
#: descriptions use ``<property>``); xacro 2 ignores them, so they are prefixed on reading.
LEGACY_TAGS = ("property", "macro", "include", "arg", "if", "unless", "insert_block")
_PACKAGE_URI = "package://"


def _legacy_tags(parse):
    """xacro's ``parse``, with the unprefixed tags of ROS 1's xacro (:data:`LEGACY_TAGS`)
    given their ``xacro:`` prefix and ``<xacro:include filename="package://PKG/...">`` read as
    ``$(find PKG)/...`` (ROS 2 descriptions write both; the PyPI xacro takes the URI for a
    relative path), in the file and every file it includes."""

    def parse_prefixed(inp, filename=None):
        doc = parse(inp, filename)
        for tag in LEGACY_TAGS:
            for el in list(doc.getElementsByTagName(tag)):
                el.tagName = el.nodeName = f"xacro:{tag}"
        for el in doc.getElementsByTagName("xacro:include"):
            uri = el.getAttribute("filename")
            pkg, _, rest = uri[len(_PACKAGE_URI) :].partition("/")
            if uri.startswith(_PACKAGE_URI) and pkg and "$" not in pkg:
                el.setAttribute("filename", f"$(find {pkg})/{rest}")
        return doc

    return parse_prefixed


def _xacro_where(top: Path) -> str:
    """Where xacro was when it failed, when that is not the top file: `` (in macro M of FILE)``."""
    macros = xacro.macrostack or []
    if macros:
        m = macros[-1]
        where = m.history[-1][-1] if m.history and m.history[-1] else None
        return f" (in macro {m.body.getAttribute('name')!r}" + (f" of {where})" if where else ")")
    files = [f for f in (xacro.filestack or []) if f]
    if files and Path(files[-1]).resolve() != top.resolve():
        return f" (in {files[-1]})"
    return ""


def _cause(e: BaseException | None, kind) -> BaseException | None:
    """The first exception of type ``kind`` (a class, or a class name) in ``e``'s chain."""
    seen = set()
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if (isinstance(kind, str) and type(e).__name__ == kind) or (
            isinstance(kind, type) and isinstance(e, kind)
        ):
            return e
        e = getattr(e, "exc", None) or e.__cause__ or e.__context__
    return None


def _default_arg_hint(top: Path, text: str) -> str:
    """`` (argument 'ur_type' is 'ur5x' by default: ...)`` when a missing file's path holds the
    default of an argument the top file declares (UR's ROS 2 description defaults ur_type to
    the non-existent 'ur5x', so that it must be given), else ""."""
    try:
        root = ET.parse(top).getroot()
    except (ET.ParseError, OSError):
        return ""
    for el in root.iter():
        if isinstance(el.tag, str) and el.tag.split("}")[-1] in ("arg", "xacro:arg"):
            name, default = el.get("name"), el.get("default") or ""
            hit = (
                len(default) > 1
                and "$" not in default
                and re.search(rf"/{re.escape(default)}(?=[/'\"\s.]|$)", text)
            )
            if name and hit:
                return (
                    f" (argument {name!r} is {default!r} there by default: give it with "
                    f"--xacro-arg {name}=VALUE, campaign.toml: xacro_args)"
                )
    return ""


def _chain_text(e: BaseException | None) -> str:
    """The messages (and file names) of ``e`` and the exceptions behind it, in one string."""
    out, seen = [], set()
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        out.append(f"{e} {getattr(e, 'filename', '') or ''}")
        e = getattr(e, "exc", None) or e.__cause__ or e.__context__
    return " ".join(out)


def _xacro_message(e: Exception) -> str:
    """xacro's exception as one line, an undefined argument said as such."""
    arg = _cause(e, "ArgException")
    if arg is not None:
        name = arg.args[0] if arg.args else "?"
        how = f"--xacro-arg {name}=VALUE (campaign.toml: xacro_args)"
        return f"argument {name!r} has no value: give it with {how}"
    text = " ".join(str(e).split())
    if isinstance(e, ET.ParseError) or type(e).__name__ == "ExpatError":
        return f"not valid XML ({text})"
    if "must not start with double underscore" in text or "invalid name(s): __" in text:
        text += (
            " (xacro refuses property names starting with '__' since 2021, 1.13.13/1.14.9; the "
            "description predates that: rename them, as its maintainers since did)"
        )
    return text or type(e).__name__


def read_urdf(
    path: str | os.PathLike,
    *,
    xacro_args: Mapping[str, str] | None = None,
    package_paths: Sequence[str | os.PathLike] = (),
) -> UrdfTree:
    """Read a robot description file (URDF, or xacro expanded first) into its kinematic tree.

    Parameters
    ----------
    path : path-like
        ``ROBOT.urdf``, or ``ROBOT.xacro`` / ``ROBOT.urdf.xacro`` (or a ``.urdf`` that declares
        the xacro namespace and uses it: xacro saved under a URDF's name, expanded as well).
    xacro_args : mapping of str to str, optional
        xacro arguments (a plain URDF takes none: refused, so a mistyped file name is seen).
    package_paths : sequence of path-like
        Folders searched for ``$(find PKG)``.

    Raises
    ------
    InputError
        Naming the file (see :func:`parse_urdf` and :func:`expand_xacro`).
    """
    src = str(path)
    if is_xacro(path):
        return parse_urdf(expand_xacro(path, xacro_args, package_paths), src)
    text = read_text_file(path, "URDF file")
    if _holds_xacro(text):  # xacro saved as .urdf: ROS's xacro command takes any name too
        return parse_urdf(expand_xacro(path, xacro_args, package_paths), src)
    if xacro_args:
        raise InputError(
            f"xacro arguments ({', '.join(xacro_args)}) given, but the file is not xacro "
            "(its name does not end in .xacro and it holds no xacro element or expression)",
            source=src,
        )
    return parse_urdf(text, src)


def _holds_xacro(text: str) -> bool:
    """Whether a file not named .xacro is xacro all the same: it declares the xacro namespace
    and uses it (an ``<xacro:...>`` element, a ``${...}`` or ``$(...)`` expression); a URDF
    xacro wrote out keeps the namespace only."""
    return "xmlns:xacro" in text and re.search(r"<xacro:|\$\{|\$\(", text) is not None


_LINK_KEYS = ("link", "name", "xyz_mm", "rpy", "beam", "compliance")
_BEAM_KEYS = ("length_mm", "E_MPa", "G_MPa", "area_mm2", "Iy_mm4", "Iz_mm4", "J_mm4", "shear_factor", "axis")


def _three(value, where: str) -> np.ndarray:
    ok = (
        isinstance(value, list)
        and len(value) == 3
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    )
    a = np.asarray(value, dtype=float) if ok else None
    if a is None or not np.all(np.isfinite(a)) or np.max(np.abs(a)) > MAX_ORIGIN_M * 1e3:
        raise InputError(f"{where}: expected three finite numbers, got {value!r}")
    return a


def _link_spring(t, where: str) -> LinkSpring:
    """One ``[[links]]`` table as a LinkSpring (InputError naming ``where`` and the key)."""
    if not isinstance(t, dict):
        raise InputError(f"{where}: expected a table (link = ..., beam or compliance)")
    unknown = sorted(set(t) - set(_LINK_KEYS))
    if unknown:
        raise InputError(f"{where}.{unknown[0]}: unknown key; valid: {', '.join(_LINK_KEYS)}")
    link = t.get("link")
    if not isinstance(link, str) or not link:
        raise InputError(f"{where}.link: expected the name of a URDF link, got {link!r}")
    name = t.get("name", link)
    if not isinstance(name, str) or not name.replace("_", "a").isalnum():
        raise InputError(
            f"{where}.name: expected letters, digits and '_' (the parameters' suffix), got {name!r}"
        )
    origin = _three(t["xyz_mm"], f"{where}.xyz_mm") if "xyz_mm" in t else None
    R = rpy_matrix(_three(t["rpy"], f"{where}.rpy")) if "rpy" in t else np.eye(3)
    if ("beam" in t) == ("compliance" in t):
        raise InputError(
            f"{where}: give either beam (its data) or compliance (a 6 x 6 matrix), not both or none"
        )
    if "compliance" in t:
        C = check_compliance_matrix(_matrix(t["compliance"], f"{where}.compliance"), f"{where}.compliance")
        return LinkSpring(link, name, origin, R, compliance=C, where=where)
    b = t["beam"]
    if not isinstance(b, dict):
        raise InputError(f"{where}.beam: expected a table of beam data ({', '.join(_BEAM_KEYS)})")
    unknown = sorted(set(b) - set(_BEAM_KEYS))
    if unknown:
        raise InputError(f"{where}.beam.{unknown[0]}: unknown key; valid: {', '.join(_BEAM_KEYS)}")
    missing = [k for k in _BEAM_KEYS[:7] if k not in b]
    if missing:
        raise InputError(f"{where}.beam: missing {', '.join(missing)} (N-mm-MPa)")
    beam = Beam(**{k: b[k] for k in _BEAM_KEYS if k in b})
    return LinkSpring(link, name, origin, R, beam=check_beam(beam, f"{where}.beam"), where=where)


def _matrix(value, where: str) -> np.ndarray:
    rows = value if isinstance(value, list) else []
    if (
        not all(
            isinstance(r, list) and all(isinstance(v, int | float) and not isinstance(v, bool) for v in r)
            for r in rows
        )
        or not rows
    ):
        raise InputError(f"{where}: expected a 6 x 6 matrix of numbers (six rows of six)")
    try:
        A = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a 6 x 6 matrix of numbers (six rows of six)") from None
    if A.shape != (6, 6):
        raise InputError(
            f"{where}: expected a 6 x 6 matrix of numbers (six rows of six), got shape {A.shape}"
        )
    return A


def rpy_matrix(rpy) -> np.ndarray:
    """URDF's roll-pitch-yaw (fixed axes x, y, z) as a rotation matrix."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def links_from_tables(tables, source: str, key: str = "links") -> tuple[LinkSpring, ...]:
    """Flexible links from parsed TOML tables (``[[links]]``; ``[[legs.links]]`` in a legs file).

    Raises
    ------
    InputError
        Naming ``source`` and the table (``links[2].beam.E_MPa: expected a positive number``).
    """
    if not isinstance(tables, list):
        raise InputError(f"{key}: expected an array of tables ([[{key}]])", source=source)
    try:
        springs = [_link_spring(t, f"{key}[{i}]") for i, t in enumerate(tables, start=1)]
    except InputError as e:
        raise e.with_source(source) from None
    # later messages (a link not on the chain) name the file and the table too
    return tuple(replace(s, where=f"{source}: {s.where}") for s in springs)


def read_links_toml(path: str | os.PathLike) -> tuple[LinkSpring, ...]:
    """A robot's flexible links from ``LINKS.toml`` (``[[links]]`` tables; docs/models.md).

    Raises
    ------
    InputError
        Naming the file and the table: not TOML, no ``[[links]]``, an unknown key, bad beam
        data, a compliance matrix that is not 6 x 6, symmetric and positive definite.
    """
    src = str(path)
    text = read_text_file(path, "TOML file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML ({e})", source=src) from None
    except RecursionError:
        raise InputError("not valid TOML: arrays or tables nested too deeply", source=src) from None
    except ValueError:  # an integer of thousands of digits
        raise InputError("not a usable TOML file: a number has thousands of digits", source=src) from None
    extra = sorted(set(data) - {"links"})
    if extra:
        raise InputError(f"{extra[0]}: unknown key; a links file holds [[links]] tables only", source=src)
    if "links" not in data:
        raise InputError("no [[links]] table: nothing bends", source=src)
    return links_from_tables(data["links"], src)
