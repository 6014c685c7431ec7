"""The results database of a campaign: one SQLite file, ``stiffmap.db``, in WAL mode.

Every row carries its provenance: the stiffmap version, a hash of the
parameters that produced it and the SHA-256 of its input file(s). Writes happen
in transactions (one per robot position for image work), so a run killed at any
moment leaves either all of a position's rows or none of them, and the next run
recomputes exactly what is missing or changed. Raw inputs are only ever read.

Arrays are stored as JSON text (row-major lists), readable from any SQLite
client. :func:`dump_content` returns the content without run-dependent columns
(timings, run ids, timestamps) for comparisons.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sqlite3
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..io import to_jsonable

__all__ = [
    "Store",
    "DB_NAME",
    "file_sha256",
    "params_hash",
    "dump_content",
    "model_fit_columns",
    "SCHEMA_VERSION",
]

DB_NAME = "stiffmap.db"
SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT, started TEXT NOT NULL, finished TEXT,
    version TEXT NOT NULL, params TEXT NOT NULL, status TEXT NOT NULL, summary TEXT);
CREATE TABLE IF NOT EXISTS files (
    path TEXT PRIMARY KEY, size INTEGER NOT NULL, mtime_ns INTEGER NOT NULL, sha256 TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS measurements (
    image TEXT PRIMARY KEY, position INTEGER NOT NULL, board_set TEXT NOT NULL,
    sha256 TEXT, params_hash TEXT NOT NULL, version TEXT NOT NULL,
    status TEXT NOT NULL, error TEXT,
    mobile2cam TEXT, mobile_cov TEXT, fixed2cam TEXT, fixed_cov TEXT, mobile2base TEXT, base_cov TEXT,
    rms_px REAL, n_corners INTEGER, tracked INTEGER, seconds REAL);
CREATE TABLE IF NOT EXISTS displacements (
    position INTEGER NOT NULL, load INTEGER NOT NULL, repeat INTEGER NOT NULL,
    unloaded TEXT NOT NULL, loaded TEXT NOT NULL, frame TEXT, d TEXT, cov TEXT,
    status TEXT NOT NULL, error TEXT, params_hash TEXT NOT NULL, version TEXT NOT NULL,
    PRIMARY KEY (position, load, repeat));
CREATE TABLE IF NOT EXISTS repeat_stats (
    position INTEGER NOT NULL, load INTEGER NOT NULL, quantity TEXT NOT NULL,
    mean REAL, std REAL, n INTEGER NOT NULL, PRIMARY KEY (position, load, quantity));
CREATE TABLE IF NOT EXISTS stiffness (
    position INTEGER PRIMARY KEY, x REAL NOT NULL, y REAL NOT NULL, z REAL NOT NULL,
    status TEXT NOT NULL, error TEXT, method TEXT,
    K TEXT, K_std TEXT, K_cov TEXT, det REAL, eigenvalues TEXT, min_principal REAL,
    K_condition REAL, design_condition REAL, rank INTEGER, dof INTEGER, n_obs INTEGER,
    residual_rms TEXT, flags TEXT, precision TEXT,
    inputs_hash TEXT NOT NULL, params_hash TEXT NOT NULL, version TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS model_fit (
    name TEXT PRIMARY KEY, model TEXT NOT NULL, status TEXT NOT NULL, error TEXT,
    params TEXT, std TEXT, cov TEXT, residuals TEXT, condition REAL, dof INTEGER,
    inputs_hash TEXT NOT NULL, version TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS model_stiffness (
    position INTEGER PRIMARY KEY, model TEXT NOT NULL, valid INTEGER NOT NULL, reason TEXT,
    K TEXT, det REAL, min_principal REAL, inputs_hash TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS model_static_error (
    recording TEXT PRIMARY KEY, model TEXT NOT NULL, valid INTEGER NOT NULL, reason TEXT,
    predicted_mm REAL, inputs_hash TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS sensor_results (
    recording TEXT PRIMARY KEY, point TEXT, direction TEXT, sha256 TEXT, params_hash TEXT NOT NULL,
    version TEXT NOT NULL, status TEXT NOT NULL, error TEXT, result TEXT);
"""

#: Columns that depend on the run, not on the inputs (left out of :func:`dump_content`).
VOLATILE = {"seconds", "started", "finished", "id", "summary"}


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def params_hash(params: Any) -> str:
    """A short, stable hash of JSON-able parameters (and the stiffmap version)."""
    text = json.dumps(to_jsonable(params), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(f"{__version__}|{text}".encode()).hexdigest()[:16]


def to_json(value: Any) -> str | None:
    """JSON text of an array or object for a TEXT column (None stays NULL)."""
    if value is None:
        return None
    return json.dumps(to_jsonable(value), separators=(",", ":"))


def from_json(text: str | None, array: bool = True):
    """Inverse of :func:`to_json` (arrays as float64 ndarray; null entries as NaN)."""
    if text is None:
        return None
    v = json.loads(text)
    if array:
        return np.array(v, dtype=float) if v is not None else None
    return v


def model_fit_columns(fit, residuals) -> dict[str, Any]:
    """The ``model_fit`` columns of a successful :class:`stiffmap.models.fit.ModelFit`."""
    return {
        "status": "ok",
        "error": None,
        "params": to_json(dict(zip(fit.names, fit.estimate, strict=True))),
        "std": to_json(dict(zip(fit.names, fit.std, strict=True))),
        "cov": to_json(fit.covariance),
        "residuals": to_json(residuals),
        "condition": float(fit.condition),
        "dof": int(fit.dof),
    }


class Store:
    """A campaign's ``stiffmap.db``.

    Use as a context manager; group writes with :meth:`transaction`.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.conn = sqlite3.connect(self.path, timeout=60, isolation_level=None)
        self.conn.row_factory = sqlite3.Row
        self.conn.execute("PRAGMA journal_mode=WAL")
        self.conn.execute("PRAGMA synchronous=NORMAL")
        self.conn.execute("PRAGMA foreign_keys=ON")
        with self.transaction():
            for stmt in _SCHEMA.strip().split(";"):
                if stmt.strip():
                    self.conn.execute(stmt)
            row = self.conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
            if row is None:
                self.conn.execute("INSERT INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
            elif int(row[0]) != SCHEMA_VERSION:
                raise RuntimeError(
                    f"{self.path}: database schema {row[0]} but this stiffmap uses {SCHEMA_VERSION}; "
                    "move the old stiffmap.db away and run again"
                )

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.conn.close()

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """BEGIN IMMEDIATE ... COMMIT (ROLLBACK on any exception, including KeyboardInterrupt)."""
        self.conn.execute("BEGIN IMMEDIATE")
        try:
            yield self.conn
        except BaseException:
            self.conn.execute("ROLLBACK")
            raise
        else:
            self.conn.execute("COMMIT")

    # ----------------------------------------------------------------- files
    def sha256(self, path: str | Path) -> str:
        """SHA-256 of a file, cached by (size, mtime) in the ``files`` table."""
        p = Path(path)
        st = p.stat()
        key = str(p.resolve())
        row = self.conn.execute("SELECT size, mtime_ns, sha256 FROM files WHERE path=?", (key,)).fetchone()
        if row is not None and row["size"] == st.st_size and row["mtime_ns"] == st.st_mtime_ns:
            return row["sha256"]
        digest = file_sha256(p)
        self.conn.execute(
            "INSERT OR REPLACE INTO files VALUES (?, ?, ?, ?)", (key, st.st_size, st.st_mtime_ns, digest)
        )
        return digest

    # ------------------------------------------------------------------ runs
    def begin_run(self, params: Any) -> int:
        with self.transaction():
            cur = self.conn.execute(
                "INSERT INTO runs (started, version, params, status) VALUES (?, ?, ?, 'running')",
                (datetime.now(UTC).isoformat(timespec="seconds"), __version__, to_json(params)),
            )
        return int(cur.lastrowid)

    def end_run(self, run_id: int, status: str, summary: Any = None) -> None:
        with self.transaction():
            self.conn.execute(
                "UPDATE runs SET finished=?, status=?, summary=? WHERE id=?",
                (datetime.now(UTC).isoformat(timespec="seconds"), status, to_json(summary), run_id),
            )

    # --------------------------------------------------------------- helpers
    def upsert(self, table: str, row: dict[str, Any]) -> None:
        """INSERT OR REPLACE one row (dict keys are column names)."""
        cols = ", ".join(row)
        marks = ", ".join("?" for _ in row)
        self.conn.execute(f"INSERT OR REPLACE INTO {table} ({cols}) VALUES ({marks})", tuple(row.values()))

    def rows(self, sql: str, args: tuple = ()) -> list[sqlite3.Row]:
        return self.conn.execute(sql, args).fetchall()


def dump_content(path: str | Path) -> dict[str, list[tuple]]:
    """Every table's rows, sorted, without run-dependent columns (for comparisons)."""
    conn = sqlite3.connect(f"file:{os.fspath(path)}?mode=ro", uri=True)
    try:
        out: dict[str, list[tuple]] = {}
        tables = [
            r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")
        ]
        for t in tables:
            if t in ("runs", "sqlite_sequence", "files"):
                continue
            cols = [r[1] for r in conn.execute(f"PRAGMA table_info({t})") if r[1] not in VOLATILE]
            rows = conn.execute(f"SELECT {', '.join(cols)} FROM {t}").fetchall()
            out[t] = sorted(rows, key=repr)
        return out
    finally:
        conn.close()
