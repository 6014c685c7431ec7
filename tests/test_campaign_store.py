"""The results database: WAL, transactions that leave nothing half-written, hash cache."""

from __future__ import annotations

import os
import sqlite3
import stat

import pytest

from stiffmap.campaign.store import Store, dump_content, file_sha256, params_hash
from stiffmap.errors import InputError
from stiffmap.io import atomic_write_text


def test_wal_and_schema(tmp_path):
    with Store(tmp_path / "stiffmap.db") as st:
        mode = st.conn.execute("PRAGMA journal_mode").fetchone()[0]
        assert mode == "wal"
        names = {r[0] for r in st.conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        assert {"measurements", "displacements", "stiffness", "model_fit", "repeat_stats"} <= names


def test_failed_transaction_leaves_nothing(tmp_path):
    db = tmp_path / "stiffmap.db"
    with Store(db) as st:
        with pytest.raises(RuntimeError):
            with st.transaction():
                st._upsert(
                    "repeat_stats",
                    {"position": 1, "load": 1, "quantity": "norm", "mean": 1.0, "std": 0.1, "n": 3},
                )
                raise RuntimeError("killed")
        assert st.repeat_stat_rows() == []
        with st.transaction():
            st._upsert(
                "repeat_stats",
                {"position": 1, "load": 1, "quantity": "norm", "mean": 1.0, "std": 0.1, "n": 3},
            )
            # Replacing a row by its key never duplicates it.
            st._upsert(
                "repeat_stats",
                {"position": 1, "load": 1, "quantity": "norm", "mean": 2.0, "std": 0.1, "n": 3},
            )
    content = dump_content(db)
    assert content["repeat_stats"] == [(1, 1, "norm", 2.0, 0.1, 3)]


def test_sha256_cache_follows_file_changes(tmp_path):
    f = tmp_path / "a.bin"
    f.write_bytes(b"abc")
    with Store(tmp_path / "stiffmap.db") as st:
        with st.transaction():
            h1 = st.sha256(f)
        assert h1 == file_sha256(f) == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        f.write_bytes(b"abcd")
        with st.transaction():
            assert st.sha256(f) == file_sha256(f) != h1


def test_params_hash_is_stable_and_sensitive():
    assert params_hash({"a": 1, "b": [1.0, 2.0]}) == params_hash({"b": [1.0, 2.0], "a": 1})
    assert params_hash({"a": 1}) != params_hash({"a": 2})


def test_dump_is_read_only(tmp_path):
    db = tmp_path / "stiffmap.db"
    Store(db).close()
    dump_content(db)
    with pytest.raises(sqlite3.OperationalError):
        conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
        conn.execute("INSERT INTO meta VALUES ('x', 'y')")


def test_atomic_write_keeps_default_permissions_and_leaves_no_temporary(tmp_path):
    p = tmp_path / "out" / "a.txt"
    atomic_write_text(p, "one")
    atomic_write_text(p, "two")
    assert p.read_text() == "two"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask
    assert [x.name for x in p.parent.iterdir()] == ["a.txt"]


def test_nested_transactions_join_the_outer_one(tmp_path):
    row = {"position": 1, "load": 1, "quantity": "norm", "mean": 1.0, "std": 0.1, "n": 3}
    with Store(tmp_path / "stiffmap.db") as st:
        with pytest.raises(RuntimeError):
            with st.transaction():
                st.save_position(1, displacements=[], repeat_stats=[row], stiffness=_stiffness_row(1))
                raise RuntimeError("killed after the inner transaction")
        assert st.repeat_stat_rows() == [] and st.stiffness_rows() == []
        st.save_position(1, displacements=[], repeat_stats=[row], stiffness=_stiffness_row(1))
        assert [r.position for r in st.stiffness_rows()] == [1]
        assert st.stiffness_inputs_hash(1) == "h1" and st.stiffness_inputs_hash(2) is None
        st.delete_positions_after(0)
        assert st.repeat_stat_rows() == [] and st.stiffness_rows() == []


def test_read_only_store_reads_and_never_writes(tmp_path):
    db = tmp_path / "stiffmap.db"
    with Store(db) as st:
        st.save_position(1, displacements=[], repeat_stats=[], stiffness=_stiffness_row(1))
    with Store(db, read_only=True) as st:
        assert [r.position for r in st.stiffness_rows()] == [1]
        with pytest.raises(InputError, match="stiffmap.db: cannot write the results database: .*readonly"):
            st.delete_positions_after(0)


def _stiffness_row(position: int) -> dict:
    return {
        "position": position,
        "x": 0.0,
        "y": 0.0,
        "z": -300.0,
        "status": "failed",
        "error": "test",
        "inputs_hash": f"h{position}",
        "params_hash": "p",
        "version": "0",
    }
