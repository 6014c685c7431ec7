"""The house rules of docs/architecture.md that a linter does not check.

The layers and the absence of import cycles are checked by import-linter (the contracts in
pyproject.toml, run by ``make test``); these tests check the two rules it cannot see:
every module's stiffmap dependencies stand at its top, and only the store speaks SQL; and
the registries' rule: only the registry of robot kinds (and each kind's own modules) names a
robot kind, only the instruments' registry (and the spec, its schema) branches on what a
campaign measures with.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

from stiffmap.kinds import ROBOT_KINDS

SRC = Path(__file__).resolve().parents[1] / "src" / "stiffmap"
MODULES = sorted(SRC.rglob("*.py"))

#: Function-level imports of stiffmap modules that must stay lazy, and why. (The command
#: modules are loaded lazily by ``stiffmap.cli.main`` through importlib, not listed here.)
LAZY_IMPORTS: dict[tuple[str, str], str] = {
    ("stiffmap/report/writer.py", ".html"): "plotly loads only when a page is written",
    ("stiffmap/report/writer.py", ".static_figures"): "matplotlib loads only when PNGs are written",
    ("stiffmap/parallel.py", "distributed"): "an optional extra, loaded only for --dask",
    ("stiffmap/capture/sources.py", "harvesters.core"): "GenICam cameras, an optional extra",
}

SQL = re.compile(
    r"\b(SELECT\s|INSERT\s+(OR\s+\w+\s+)?INTO|UPDATE\s+\w+\s+SET|DELETE\s+FROM|CREATE\s+TABLE|DROP\s+TABLE)"
)


@functools.cache
def _tree(path: Path) -> ast.Module:
    """A module's syntax tree, parsed once for all the rules."""
    return ast.parse(path.read_text(encoding="utf-8"))


def _rel(path: Path) -> str:
    return path.relative_to(SRC.parent).as_posix()


def _function_level_imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every stiffmap import made inside a function body."""
    tree = _tree(path)
    found = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
            if in_function and isinstance(child, ast.ImportFrom):
                if child.level or (child.module or "").startswith("stiffmap"):
                    found.append((child.lineno, "." * child.level + (child.module or "")))
            elif in_function and isinstance(child, ast.Import):
                found.extend((child.lineno, a.name) for a in child.names if a.name.startswith("stiffmap"))
            visit(child, inside)

    visit(tree, False)
    return found


def test_stiffmap_imports_stand_at_the_top():
    late = [
        f"{_rel(path)}:{line} imports {mod} inside a function"
        for path in MODULES
        for line, mod in _function_level_imports(path)
        if (_rel(path), mod) not in LAZY_IMPORTS
    ]
    assert not late, "\n".join(late)


def test_only_the_store_speaks_sql():
    sql = [
        f"{_rel(path)}:{node.lineno}: {node.value.strip()[:60]!r}"
        for path in MODULES
        if _rel(path) != "stiffmap/campaign/store.py"
        for node in ast.walk(_tree(path))
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and SQL.search(node.value)
    ]
    assert not sql, "SQL outside campaign/store.py:\n" + "\n".join(sql)


#: Where a robot kind's name may stand: the registry and the mechanisms' own modules.
KIND_HOMES = (
    "stiffmap/kinds/",
    "stiffmap/models/delta.py",
    "stiffmap/models/prr3.py",
    "stiffmap/models/serial.py",
    "stiffmap/models/arm6.py",
    "stiffmap/models/legs.py",
    "stiffmap/models/legs_file.py",
)
#: Other places that hold a kind's name, and why (module, name) -> reason.
KIND_NAME_REASONS: dict[tuple[str, str], str] = {
    (
        "stiffmap/sim/robot.py",
        "urdf",
    ): "the campaign.toml key of a URDF robot's file (robot.urdf), not the kind",
    ("stiffmap/geometry.py", "delta"): "the name of a displacement argument (delta) in a message",
    ("stiffmap/models/legs6.py", "hexapod"): "the shipped hexapod TOML's robot name, not the test-bed's",
}
#: Where a campaign's kind ("vision", "sensor") may be compared: the instruments' registry and
#: the spec (its schema); others with their reason.
INSTRUMENT_HOMES = ("stiffmap/campaign/instruments.py", "stiffmap/campaign/spec.py")
INSTRUMENT_REASONS: dict[str, str] = {
    "stiffmap/campaign/runner.py": "the cameras' runner refuses another instrument's campaign",
    "stiffmap/campaign/truth.py": "truth.json's own 'kind' field (a file format)",
    "stiffmap/capture/plan.py": "stiffmap capture drives one camera: the camera instrument's tool",
    "stiffmap/capture/cameras.py": "truth.json's own 'kind' field (a file format)",
    "stiffmap/report/data.py": "the report's data contract checks its own 'kind' field",
}


def _kind_names() -> set[str]:
    return {k.name for k in ROBOT_KINDS.values()} | {
        k.testbed.name for k in ROBOT_KINDS.values() if k.testbed is not None
    }


def _named(path: Path, names: set[str]) -> list[tuple[int, str]]:
    """(line, name) of every string constant of ``path`` that is one of ``names``."""
    tree = _tree(path)
    return [
        (n.lineno, n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in names
    ]


def _compared(path: Path, names: set[str]) -> list[tuple[int, str]]:
    """(line, name) of every comparison of something with one of ``names`` (==, !=, in)."""
    tree = _tree(path)
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Compare):
            for c in ast.walk(n):
                if isinstance(c, ast.Constant) and isinstance(c.value, str) and c.value in names:
                    out.append((n.lineno, c.value))
    return out


def test_only_the_registry_names_robot_kinds():
    """A kind's name outside the registry is a branch the next kind would have to find."""
    names = _kind_names()
    found = [
        f"{_rel(path)}:{line}: {name!r}"
        for path in MODULES
        if not _rel(path).startswith(KIND_HOMES)
        for line, name in _named(path, names)
        if (_rel(path), name) not in KIND_NAME_REASONS
    ]
    assert not found, "robot kinds named outside stiffmap.kinds:\n" + "\n".join(found)


def test_only_the_instruments_registry_branches_on_the_campaign_kind():
    found = [
        f"{_rel(path)}:{line}: {name!r}"
        for path in MODULES
        if _rel(path) not in INSTRUMENT_HOMES and _rel(path) not in INSTRUMENT_REASONS
        for line, name in _compared(path, {"vision", "sensor"})
    ]
    assert not found, "campaign kinds compared outside campaign.instruments:\n" + "\n".join(found)


def test_the_rules_see_violations(tmp_path):
    """The checks above find what they look for, on a made-up module."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        "import stiffmap.io\n"
        "def f():\n"
        "    from .geometry import as_transform\n"
        "    import stiffmap.camera, numpy\n"
        "    return 'SELECT x FROM t'\n"
    )
    assert _function_level_imports(bad) == [(3, ".geometry"), (4, "stiffmap.camera")]
    assert SQL.search("SELECT x FROM t") and SQL.search("INSERT OR REPLACE INTO images")
    assert not SQL.search("Select the board") and not SQL.search("update the selection")
    branchy = tmp_path / "branchy.py"
    branchy.write_text(
        "def f(spec):\n    if spec.kind == 'vision' and spec.robot.model in ('delta', 'x'):\n        pass\n"
    )
    assert _named(branchy, {"delta", "3prr"}) == [(2, "delta")]
    assert _compared(branchy, {"vision", "sensor"}) == [(2, "vision")]


def test_no_submodule_shadows_a_name_its_package_exports():
    """``from stiffmap.vision import measure_files`` must stay the function: a submodule of the
    same name replaces the package's attribute once anything imports it (the README's tour
    failed after another test had imported ``stiffmap.vision.measure_files``)."""
    clashes = []
    for init in SRC.rglob("__init__.py"):
        exported = {
            elt.value
            for node in ast.walk(_tree(init))
            if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in node.targets)
            for elt in getattr(node.value, "elts", [])
            if isinstance(elt, ast.Constant)
        }
        subs = {p.stem for p in init.parent.glob("*.py")} | {
            p.name for p in init.parent.iterdir() if p.is_dir()
        }
        clashes += [f"{_rel(init.parent)}: {name}" for name in sorted(exported & subs)]
    assert not clashes, "package names that a submodule of the same name shadows:\n" + "\n".join(clashes)
