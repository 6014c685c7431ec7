"""The results database: WAL, transactions that leave nothing half-written, hash cache."""

from __future__ import annotations

import sqlite3

import pytest

from stiffmap.campaign.store import Store, dump_content, file_sha256, params_hash


def test_wal_and_schema(tmp_path):
    with Store(tmp_path / "stiffmap.db") as st:
        mode = st.conn.execute("PRAGMA journal_mode").fetchone()[0]
        assert mode == "wal"
        names = {r[0] for r in st.rows("SELECT name FROM sqlite_master WHERE type='table'")}
        assert {"measurements", "displacements", "stiffness", "model_fit", "repeat_stats"} <= names


def test_failed_transaction_leaves_nothing(tmp_path):
    db = tmp_path / "stiffmap.db"
    with Store(db) as st:
        with pytest.raises(RuntimeError):
            with st.transaction():
                st.upsert(
                    "repeat_stats",
                    {"position": 1, "load": 1, "quantity": "norm", "mean": 1.0, "std": 0.1, "n": 3},
                )
                raise RuntimeError("killed")
        assert st.rows("SELECT COUNT(*) FROM repeat_stats")[0][0] == 0
        with st.transaction():
            st.upsert(
                "repeat_stats",
                {"position": 1, "load": 1, "quantity": "norm", "mean": 1.0, "std": 0.1, "n": 3},
            )
            # Replacing a row by its key never duplicates it.
            st.upsert(
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
    import os
    import stat

    from stiffmap.io import atomic_write_text

    p = tmp_path / "out" / "a.txt"
    atomic_write_text(p, "one")
    atomic_write_text(p, "two")
    assert p.read_text() == "two"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask
    assert [x.name for x in p.parent.iterdir()] == ["a.txt"]
