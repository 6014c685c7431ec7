"""The house rules of docs/architecture.md that a linter does not check.

The layers and the absence of import cycles are checked by import-linter (the contracts in
pyproject.toml, run by ``make test``); these tests check the two rules it cannot see:
every module's stiffmap dependencies stand at its top, and only the store speaks SQL.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

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


def _rel(path: Path) -> str:
    return path.relative_to(SRC.parent).as_posix()


def _function_level_imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every stiffmap import made inside a function body."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
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


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_stiffmap_imports_stand_at_the_top(path):
    late = [
        f"{_rel(path)}:{line} imports {mod} inside a function"
        for line, mod in _function_level_imports(path)
        if (_rel(path), mod) not in LAZY_IMPORTS
    ]
    assert not late, "\n".join(late)


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_only_the_store_speaks_sql(path):
    if _rel(path) == "stiffmap/campaign/store.py":
        return
    tree = ast.parse(path.read_text(encoding="utf-8"))
    sql = [
        f"{_rel(path)}:{node.lineno}: {node.value.strip()[:60]!r}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and SQL.search(node.value)
    ]
    assert not sql, "SQL outside campaign/store.py:\n" + "\n".join(sql)


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
