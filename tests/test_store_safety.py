"""A ``stiffmap.db`` that is not stiffmap's is refused before any write; damaged values are named.

Another program's SQLite file named ``stiffmap.db`` used to receive stiffmap's tables (and its
WAL mode) before the layout check refused it; a database whose measured K was edited to NULL,
NaN or 2x2, or whose model rows hold a list where parameters belong, made ``report`` and
``run`` end in an internal error. Both are now one line naming the file (and the table, row
and column), exit 2, with the file's bytes unchanged.
"""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest
from helpers.fuzz_campaign import bare_vision_seed
from hypothesis import given, settings
from hypothesis import strategies as st

from stiffmap.campaign.store import DB_NAME, Store
from stiffmap.cli import main
from stiffmap.errors import InputError

STIFFMAP_TABLES = ("meta", "runs", "files", "measurements", "stiffness", "model_fit", "displacements")


def _foreign(path: Path, statements: list[str]) -> bytes:
    conn = sqlite3.connect(path)
    for s in statements:
        conn.execute(s)
    conn.commit()
    conn.close()
    return path.read_bytes()


def _untouched(path: Path, before: bytes) -> None:
    assert path.read_bytes() == before
    assert not path.with_name(path.name + "-wal").exists()


@pytest.mark.parametrize(
    "statements",
    [
        ["CREATE TABLE users (name TEXT, password TEXT)", "INSERT INTO users VALUES ('ada', 'x')"],
        ["CREATE TABLE stiffness (a TEXT, b REAL)", "INSERT INTO stiffness VALUES ('x', 1.0)"],
        [
            "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
            "CREATE VIEW v AS SELECT * FROM meta",
        ],
        ["CREATE TABLE runs (id INTEGER)", "CREATE TABLE meta (key TEXT, value TEXT)"],
    ],
    ids=["other tables", "a table of stiffmap's name", "a view", "no schema version"],
)
def test_another_programs_database_is_refused_before_any_write(tmp_path, statements):
    db = tmp_path / DB_NAME
    before = _foreign(db, statements)
    for read_only in (False, True):
        with pytest.raises(InputError, match="not a stiffmap results database") as e:
            Store(db, read_only=read_only)
        assert str(e.value).startswith(f"{db}: ") and "move it away" in str(e.value)
        _untouched(db, before)


def test_an_empty_sqlite_file_is_taken(tmp_path):
    """Nothing in it can be lost (a database stiffmap created and was stopped before its tables)."""
    db = tmp_path / DB_NAME
    _foreign(db, ["CREATE TABLE t (a)", "DROP TABLE t"])
    assert db.stat().st_size > 0
    with Store(db) as store:
        assert store.stiffness_rows() == []


@settings(deadline=None)
@given(
    tables=st.lists(
        st.tuples(
            st.sampled_from((*STIFFMAP_TABLES, "users", "data", "log", "stiffness_old", "Meta")),
            st.lists(
                st.sampled_from(("id", "name", "value", "key", "K", "status", "x")),
                min_size=1,
                max_size=4,
                unique=True,
            ),
        ),
        min_size=1,
        max_size=4,
        unique_by=lambda t: t[0].lower(),
    ),
    version=st.sampled_from((None, "3", "1", "99", "")),
)
@pytest.mark.fuzz
def test_any_foreign_schema_is_refused_or_read_without_a_change(tmp_path_factory, tables, version):
    """Random schemas of another program (some tables with stiffmap's names, a ``meta`` with or
    without a schema version): an InputError naming the file with its bytes unchanged, or (a
    genuine stiffmap layout) opened."""
    db = tmp_path_factory.mktemp("db") / DB_NAME
    statements = [f"CREATE TABLE {name} ({', '.join(cols)})" for name, cols in tables]
    names = {n for n, _ in tables}
    if version is not None and "meta" in names and {"key", "value"} <= set(dict(tables)["meta"]):
        statements.append(f"INSERT INTO meta (key, value) VALUES ('schema_version', '{version}')")
    before = _foreign(db, statements)
    try:
        Store(db).close()
    except InputError as e:
        assert str(e).startswith(f"{db}: ")
        _untouched(db, before)
    else:  # taken: only stiffmap's tables, and a schema version it knows
        assert names <= set(STIFFMAP_TABLES) and len(statements) > len(tables)


@pytest.fixture(scope="module")
def measured(tmp_path_factory) -> Path:
    """The small vision seed, run once (two positions, with the model fit)."""
    root = tmp_path_factory.mktemp("run") / "c"
    for name, data in bare_vision_seed().items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    assert main.main(["run", str(root), "--quiet", "--workers", "1", "--no-report"]) == 0
    return root


DAMAGE = [
    ("UPDATE stiffness SET K = NULL", "table 'stiffness', position 1: K is NULL"),
    ("UPDATE stiffness SET K = '[[NaN,0,0],[0,1,0],[0,0,1]]'", "K holds NaN"),
    ("UPDATE stiffness SET K = '[[1,2],[3,4]]'", "table 'stiffness', position 1: K_std is 3x3 where"),
    ("UPDATE stiffness SET K_std = '[[1]]'", "K_std is 1x1 where the stiffness matrices are 3x3"),
    ("UPDATE stiffness SET eigenvalues = '7'", "eigenvalues is not a list of finite numbers"),
    ("UPDATE model_stiffness SET K = '[[1]]'", "table 'model_stiffness', position 1: K is 1x1"),
    ("UPDATE model_fit SET params = '[1, 2]'", "table 'model_fit', name stiffness: params is not an object"),
    ("UPDATE model_fit SET params = NULL", "params is NULL"),
    ('UPDATE model_fit SET std = \'{"k_theta": "a"}\'', "std is not an object of parameter values"),
    ("UPDATE displacements SET d = '[1, 2]'", "position 1, load 1, repeat 1: d is not a displacement"),
    ("UPDATE displacements SET cov = '[[1]]'", "cov is not the 6x6 covariance of the displacement"),
    ("UPDATE measurements SET mobile2cam = '[[1,2],[3,4]]'", "mobile2cam is not a 4x4 transform"),
]


@pytest.mark.parametrize("sql, said", DAMAGE, ids=[s for s, _ in DAMAGE])
def test_a_damaged_value_is_named_by_report_and_run(measured, tmp_path, sql, said):
    root = tmp_path / "c"
    shutil.copytree(measured, root)
    conn = sqlite3.connect(root / DB_NAME)
    assert conn.execute(sql).rowcount > 0
    conn.commit()
    conn.close()
    before = (root / DB_NAME).read_bytes()
    for read_only in (True, False):
        with pytest.raises(InputError) as e:
            Store(root / DB_NAME, read_only=read_only)
        assert str(e.value).startswith(f"{root / DB_NAME}: damaged or edited: ")
        assert said in str(e.value)
    assert (root / DB_NAME).read_bytes() == before


@pytest.mark.parametrize("command", ["report", "run"])
def test_report_and_run_on_a_damaged_database_exit_2_with_one_line(measured, tmp_path, capsys, command):
    root = tmp_path / "c"
    shutil.copytree(measured, root)
    conn = sqlite3.connect(root / DB_NAME)
    conn.execute("UPDATE stiffness SET K = '[[1,2],[3,4]]', K_std = '[[1,2],[3,4]]'")
    conn.commit()
    conn.close()
    argv = (
        [command, str(root), "--no-png"]
        if command == "report"
        else [command, str(root), "--quiet", "--workers", "1"]
    )
    assert main.main(argv) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "internal error" not in err
    assert "table 'model_stiffness', position 1: K is 3x3 where the stiffness matrices are 2x2" in lines[0]


def test_a_checked_database_is_not_read_again_until_it_changes(measured, tmp_path, monkeypatch):
    """The value check reads every measured value: once per state of the file in a process."""
    import stiffmap.campaign.store as store

    root = tmp_path / "c"
    shutil.copytree(measured, root)
    calls = []
    check = store._check_values
    monkeypatch.setattr(store, "_check_values", lambda conn, path: (calls.append(path), check(conn, path)))
    for read_only in (True, True, False, True):
        Store(root / DB_NAME, read_only=read_only).close()
    assert len(calls) == 1
    conn = sqlite3.connect(root / DB_NAME)
    conn.execute("UPDATE stiffness SET K = NULL")
    conn.commit()
    conn.close()
    with pytest.raises(InputError, match="K is NULL"):
        Store(root / DB_NAME, read_only=True)
    assert len(calls) == 2
