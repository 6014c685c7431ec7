"""The results database of a campaign: one SQLite file, ``stiffmap.db``, in WAL mode.

Every row carries its provenance: the stiffmap version, a hash of the
parameters that produced it and the SHA-256 of its input file(s). Writes happen
in transactions (one per robot position for image work), so a run killed at any
moment leaves either all of a position's rows or none of them, and the next run
recomputes exactly what is missing or changed. Raw inputs are only ever read.

Every SQL statement of stiffmap is in this module: the rest of the code reads
and writes the results through :class:`Store`'s methods, named for what they
mean. Arrays are stored as JSON text (row-major lists), readable from any SQLite
client; what the methods return is typed (:mod:`stiffmap.campaign.records`: one frozen
dataclass per table, its JSON columns decoded once, here). :func:`dump_content` returns the
content without run-dependent columns (timings, run ids, timestamps) for comparisons.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
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
from ..errors import InputError
from ..io import to_jsonable
from .records import (
    ARRAY,
    DisplacementRecord,
    MeasurementRecord,
    ModelFitRecord,
    ModelStiffnessRecord,
    RepeatStatRecord,
    SensorResultRecord,
    StiffnessRecord,
)

__all__ = [
    "Store",
    "ImageCounts",
    "DB_NAME",
    "file_sha256",
    "params_hash",
    "dump_content",
    "model_fit_columns",
    "SCHEMA_VERSION",
    "remove_database",
    "record_of",
]

DB_NAME = "stiffmap.db"
SCHEMA_VERSION = 5

#: Columns added since schema 1, added in place to an older database (its rows are kept; the
#: revisions in the parameter hashes make the next run recompute what they would hold).
_ADDED_COLUMNS = {
    2: (
        ("measurements", "mobile_cal_jac"),
        ("measurements", "fixed_cal_jac"),
        ("displacements", "cov_calibration"),
        ("stiffness", "K_cov_calibration"),
    ),
    3: (("measurements", "per_camera"),),
    4: (("model_fit", "robot"),),
    5: (("model_fit", "info"),),
}

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
    rms_px REAL, n_corners INTEGER, tracked INTEGER, seconds REAL,
    mobile_cal_jac TEXT, fixed_cal_jac TEXT, per_camera TEXT);
CREATE TABLE IF NOT EXISTS displacements (
    position INTEGER NOT NULL, load INTEGER NOT NULL, repeat INTEGER NOT NULL,
    unloaded TEXT NOT NULL, loaded TEXT NOT NULL, frame TEXT, d TEXT, cov TEXT,
    status TEXT NOT NULL, error TEXT, params_hash TEXT NOT NULL, version TEXT NOT NULL,
    cov_calibration TEXT, PRIMARY KEY (position, load, repeat));
CREATE TABLE IF NOT EXISTS repeat_stats (
    position INTEGER NOT NULL, load INTEGER NOT NULL, quantity TEXT NOT NULL,
    mean REAL, std REAL, n INTEGER NOT NULL, PRIMARY KEY (position, load, quantity));
CREATE TABLE IF NOT EXISTS stiffness (
    position INTEGER PRIMARY KEY, x REAL NOT NULL, y REAL NOT NULL, z REAL NOT NULL,
    status TEXT NOT NULL, error TEXT, method TEXT,
    K TEXT, K_std TEXT, K_cov TEXT, det REAL, eigenvalues TEXT, min_principal REAL,
    K_condition REAL, design_condition REAL, rank INTEGER, dof INTEGER, n_obs INTEGER,
    residual_rms TEXT, flags TEXT, precision TEXT,
    inputs_hash TEXT NOT NULL, params_hash TEXT NOT NULL, version TEXT NOT NULL, K_cov_calibration TEXT);
CREATE TABLE IF NOT EXISTS model_fit (
    name TEXT PRIMARY KEY, model TEXT NOT NULL, status TEXT NOT NULL, error TEXT,
    params TEXT, std TEXT, cov TEXT, residuals TEXT, condition REAL, dof INTEGER,
    inputs_hash TEXT NOT NULL, version TEXT NOT NULL, robot TEXT, info TEXT);
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

#: Tables whose rows belong to one robot position (column ``position``).
POSITION_TABLES = ("measurements", "displacements", "repeat_stats", "stiffness", "model_stiffness")

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
    try:
        v = json.loads(text)
    except (ValueError, TypeError, RecursionError) as e:
        raise InputError(
            f"a stored value is not what stiffmap wrote ({type(e).__name__}: {str(e)[:80]}): the database "
            "was edited or damaged; move it away (stiffmap never deletes it) and run again",
            source=DB_NAME,
        ) from None
    if array:
        return np.array(v, dtype=float) if v is not None else None
    return v


def _decoded(text: str | None, how: str):
    value = from_json(text, array=how == ARRAY)
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    return value


def record_of(cls: type, row) -> Any:
    """A record of ``cls`` (:mod:`~stiffmap.campaign.records`) from a row: a database row or a
    dict of the columns as they are written (JSON text), its JSON columns decoded.

    Raises
    ------
    InputError
        A JSON column that does not hold what stiffmap wrote (an edited database).
    """
    keys = set(row.keys())
    values = {f.name: row[f.name] if f.name in keys else None for f in dataclasses.fields(cls)}
    for name, how in cls.JSON.items():
        values[name] = _decoded(values[name], how)
    return cls(**values)


@dataclasses.dataclass(frozen=True)
class ImageCounts:
    """The images (image sets, with a rig) of a vision campaign's measurements, by outcome.

    Attributes
    ----------
    total, measured, failed : int
        Images in the database; those with a pose of the mobile target; the others.
    positions : int
        Positions with at least one image.
    """

    total: int
    measured: int
    failed: int
    positions: int


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
        "info": to_json([str(n) for n in getattr(fit, "info", ())]),
    }


class Store:
    """A campaign's ``stiffmap.db``: every read and write of the results, by what it means.

    Use as a context manager. Each write method is one transaction; group several
    in :meth:`transaction` to make them one.

    A file that is not a stiffmap database (not SQLite, damaged, truncated, another
    program's tables, another schema version), or that cannot be written (read-only,
    locked by another run, a full disk), is an :class:`~stiffmap.errors.InputError`
    naming it and saying what to do, when it is opened or at the first method that meets
    the problem. The file is never deleted or rewritten to "repair" it.

    Parameters
    ----------
    path : path
        The database file (created with its tables unless ``read_only``).
    read_only : bool
        Open an existing database for reading only (no table is created, nothing
        can be written), e.g. beside a run in progress.
    timeout : float
        Seconds to wait for a lock held by another connection.
    """

    def __init__(self, path: str | Path, *, read_only: bool = False, timeout: float = 60) -> None:
        self.path = Path(path)
        self.conn = None
        self._trusted = False  # its values checked (or written here): see close()
        # As this process left it (before this connection writes anything: WAL files change).
        self._known = self.path.is_file() and _TRUSTED.get(self.path.resolve()) == _file_state(self.path)
        if self.path.is_dir():
            raise InputError(
                "is a folder; the results database must be a file (move it away)", source=str(path)
            )
        if read_only and not self.path.is_file():
            raise InputError("no results database (run 'stiffmap run' first)", source=str(path))
        try:
            if read_only:
                self.conn = sqlite3.connect(f"file:{os.fspath(self.path)}?mode=ro", uri=True, timeout=timeout)
                self.conn.row_factory = sqlite3.Row
                self._check_file()
                _check_owner(self.conn, self.path)
                self._check_values()
                return
            existed = self.path.is_file() and self.path.stat().st_size > 0
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.conn = sqlite3.connect(self.path, timeout=timeout, isolation_level=None)
            self.conn.row_factory = sqlite3.Row
            if existed:  # before anything is written to it (WAL mode, tables)
                self._check_file()
                _check_owner(self.conn, self.path)
            self.conn.execute("PRAGMA journal_mode=WAL")
            self.conn.execute("PRAGMA synchronous=NORMAL")
            self.conn.execute("PRAGMA foreign_keys=ON")
            with self.transaction():
                for stmt in _SCHEMA.strip().split(";"):
                    if stmt.strip():
                        self.conn.execute(stmt)
                row = self.conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
                if row is not None and str(row[0]) in {str(v) for v in range(1, SCHEMA_VERSION)}:
                    self._add_columns(int(row[0]))
                    row = None
                if row is None:
                    self.conn.execute(
                        "INSERT OR REPLACE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),)
                    )
                elif str(row[0]) != str(SCHEMA_VERSION):
                    raise InputError(
                        f"database schema {str(row[0])[:20]!r} but this stiffmap uses {SCHEMA_VERSION}; "
                        f"move the old {DB_NAME} away (nothing was changed in it) and run again",
                        source=str(self.path),
                    )
            self._check_layout()
            if existed:
                self._check_values()
            self._trusted = True
        except InputError:
            self.close()
            raise
        except sqlite3.DatabaseError as e:
            self.close()
            raise self._input_error(e) from None

    def _add_columns(self, old: int) -> None:
        """Bring a database of schema ``old`` to this one: add the columns it lacks (rows kept)."""
        for version in range(old + 1, SCHEMA_VERSION + 1):
            for table, column in _ADDED_COLUMNS.get(version, ()):
                have = {r[1] for r in self.conn.execute(f"PRAGMA table_info({table})")}
                if column not in have:
                    self.conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} TEXT")

    def _check_file(self) -> None:
        """InputError unless the file is an undamaged SQLite database (SQLite's quick check)."""
        try:
            rows = self.conn.execute("PRAGMA quick_check").fetchall()
        except UnicodeDecodeError:  # the check's report quotes damaged bytes
            rows = []
        if not rows or rows[0][0] != "ok":
            raise sqlite3.DatabaseError("database disk image is malformed")

    def _check_layout(self) -> None:
        """InputError when a table lacks a column of stiffmap's (another program's database)."""
        for table, columns in _columns().items():
            have = {r[1] for r in self.conn.execute(f"PRAGMA table_info({table})")}
            lacking = [c for c in columns if c not in have]
            if lacking:
                raise InputError(
                    f"not a stiffmap results database: table {table!r} lacks the column(s) "
                    f"{', '.join(lacking)}; move it away (nothing was changed in it) and run again",
                    source=str(self.path),
                )

    def _input_error(self, e: sqlite3.Error) -> InputError:
        """The user's view of a database error: what is wrong with the file, and what to do."""
        text = str(e)
        low = text.lower()
        if "not a database" in low or "malformed" in low or "corrupt" in low or "damaged" in low:
            what = (
                f"not a readable SQLite database (damaged, or another file named {DB_NAME}): {text}; "
                "move it away (stiffmap never deletes it) and run again: the raw inputs are untouched"
            )
        elif "readonly" in low or "read-only" in low:
            what = f"cannot write the results database: {text} (no permission, or a read-only disk)"
        elif "unable to open" in low:
            what = f"cannot open the results database: {text} (no permission, or the folder is missing)"
        elif "locked" in low or "busy" in low:
            what = f"the results database is in use ({text}): is another 'stiffmap run' working on it?"
        elif "disk" in low or "full" in low or "i/o" in low:
            what = f"cannot write the results database: {text}"
        else:
            what = f"results database error: {text}; move it away and run again if it persists"
        return InputError(what, source=str(self.path))

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_values(self) -> None:
        """:func:`_check_values`, once per state of the file in this process (a command opens its
        database several times; the check reads every measured value, 0.2 s per 1000 images)."""
        if not self._known:
            _check_values(self.conn, self.path)
        self._trusted = True

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None
            if self._trusted:  # what it holds now was checked or written by stiffmap
                _TRUSTED[self.path.resolve()] = _file_state(self.path)

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """BEGIN IMMEDIATE ... COMMIT (ROLLBACK on any exception, including KeyboardInterrupt).

        Inside another transaction it joins it: the outer one commits or rolls back everything.
        """
        if self.conn.in_transaction:
            yield self.conn
            return
        try:
            self.conn.execute("BEGIN IMMEDIATE")
        except sqlite3.DatabaseError as e:
            raise self._input_error(e) from None
        try:
            yield self.conn
        except BaseException:
            with contextlib.suppress(sqlite3.Error):
                self.conn.execute("ROLLBACK")
            raise
        else:
            try:
                self.conn.execute("COMMIT")
            except sqlite3.DatabaseError as e:
                raise self._input_error(e) from None

    def _upsert(self, table: str, row: dict[str, Any]) -> None:
        """INSERT OR REPLACE one row (dict keys are column names)."""
        cols = ", ".join(row)
        marks = ", ".join("?" for _ in row)
        self.conn.execute(f"INSERT OR REPLACE INTO {table} ({cols}) VALUES ({marks})", tuple(row.values()))

    def _rows(self, sql: str, args: tuple = ()) -> list[sqlite3.Row]:
        return self.conn.execute(sql, args).fetchall()

    # ----------------------------------------------------------------- files
    def sha256(self, path: str | Path) -> str:
        """SHA-256 of a file, cached by (size, mtime) in the ``files`` table."""
        p = Path(path)
        st = p.stat()
        key = str(p.resolve())
        with self.transaction():
            row = self.conn.execute(
                "SELECT size, mtime_ns, sha256 FROM files WHERE path=?", (key,)
            ).fetchone()
            if row is not None and row["size"] == st.st_size and row["mtime_ns"] == st.st_mtime_ns:
                return row["sha256"]
            digest = file_sha256(p)
            self.conn.execute(
                "INSERT OR REPLACE INTO files VALUES (?, ?, ?, ?)", (key, st.st_size, st.st_mtime_ns, digest)
            )
        return digest

    # ------------------------------------------------------------------ runs
    def begin_run(self, params: Any) -> int:
        """Record the start of a run (its parameters); return its id."""
        with self.transaction():
            cur = self.conn.execute(
                "INSERT INTO runs (started, version, params, status) VALUES (?, ?, ?, 'running')",
                (datetime.now(UTC).isoformat(timespec="seconds"), __version__, to_json(params)),
            )
        return int(cur.lastrowid)

    def end_run(self, run_id: int, status: str, summary: Any = None) -> None:
        """Record the end of a run: its status and a summary."""
        with self.transaction():
            self.conn.execute(
                "UPDATE runs SET finished=?, status=?, summary=? WHERE id=?",
                (datetime.now(UTC).isoformat(timespec="seconds"), status, to_json(summary), run_id),
            )

    # ------------------------------------------------- vision: per position
    def delete_positions_after(self, last: int) -> None:
        """Remove every row of the positions numbered above ``last`` (no longer in the spec)."""
        with self.transaction():
            for table in POSITION_TABLES:
                self.conn.execute(f"DELETE FROM {table} WHERE position > ?", (last,))

    def measurement_rows(self, position: int | None = None) -> list[MeasurementRecord]:
        """``measurements``: of one position, or all of them by position and image."""
        if position is not None:
            rows = self._rows("SELECT * FROM measurements WHERE position=?", (position,))
        else:
            rows = self._rows("SELECT * FROM measurements ORDER BY position, image")
        return [record_of(MeasurementRecord, r) for r in rows]

    def image_counts(self) -> ImageCounts:
        """How many images were measured and how many failed (the report's set-up summary)."""
        rows = self._rows(
            "SELECT COUNT(*) AS total, SUM(status='ok' AND mobile2cam IS NOT NULL) AS measured, "
            "COUNT(DISTINCT position) AS positions FROM measurements"
        )
        r = rows[0]
        total, measured = int(r["total"] or 0), int(r["measured"] or 0)
        return ImageCounts(total, measured, total - measured, int(r["positions"] or 0))

    def first_measured_image(self) -> MeasurementRecord | None:
        """The first image (by position, then name) in which the mobile target was measured."""
        rows = self._rows(
            "SELECT * FROM measurements WHERE status='ok' AND mobile2cam IS NOT NULL "
            "ORDER BY position, image LIMIT 1"
        )
        return record_of(MeasurementRecord, rows[0]) if rows else None

    def stiffness_inputs_hash(self, position: int) -> str | None:
        """The hash of the inputs the stored stiffness of a position was derived from."""
        rows = self._rows("SELECT inputs_hash, status FROM stiffness WHERE position=?", (position,))
        return rows[0]["inputs_hash"] if rows else None

    def save_position(
        self,
        position: int,
        *,
        displacements: list[dict[str, Any]],
        repeat_stats: list[dict[str, Any]],
        stiffness: dict[str, Any],
        measurements: list[dict[str, Any]] | None = None,
    ) -> None:
        """Replace a position's derived rows (and its measurements, when given) in one transaction.

        Rows are dicts of column values; ``measurements=None`` keeps the stored ones.
        """
        with self.transaction():
            if measurements is not None:
                self.conn.execute("DELETE FROM measurements WHERE position=?", (position,))
                for row in measurements:
                    self._upsert("measurements", row)
            for table in ("displacements", "repeat_stats", "stiffness"):
                self.conn.execute(f"DELETE FROM {table} WHERE position=?", (position,))
            for row in displacements:
                self._upsert("displacements", row)
            for row in repeat_stats:
                self._upsert("repeat_stats", row)
            self._upsert("stiffness", stiffness)

    def set_stiffness_flags(self, position: int, flags: list[str]) -> None:
        """Replace the flags of a position's K (the campaign's decision: :mod:`~stiffmap.campaign.flags`)."""
        with self.transaction():
            self.conn.execute("UPDATE stiffness SET flags=? WHERE position=?", (to_json(flags), position))

    def stiffness_rows(self) -> list[StiffnessRecord]:
        """``stiffness`` by position."""
        return [
            record_of(StiffnessRecord, r) for r in self._rows("SELECT * FROM stiffness ORDER BY position")
        ]

    def displacement_rows(self, *, only_ok: bool = False) -> list[DisplacementRecord]:
        """``displacements`` by position, load case and repeat (``only_ok``: the measured ones)."""
        where = " WHERE status='ok'" if only_ok else ""
        rows = self._rows(f"SELECT * FROM displacements{where} ORDER BY position, load, repeat")
        return [record_of(DisplacementRecord, r) for r in rows]

    def repeat_stat_rows(self) -> list[RepeatStatRecord]:
        """``repeat_stats`` by position, load case and quantity."""
        rows = self._rows("SELECT * FROM repeat_stats ORDER BY position, load, quantity")
        return [record_of(RepeatStatRecord, r) for r in rows]

    # ---------------------------------------------------------------- models
    def save_model_stiffness(self, fit: dict[str, Any], positions: list[dict[str, Any]]) -> None:
        """Store a model fit to the measured stiffness and the model's K per position (one transaction)."""
        with self.transaction():
            self._upsert("model_fit", fit)
            for row in positions:
                self._upsert("model_stiffness", row)

    def model_stiffness_rows(self) -> list[ModelStiffnessRecord]:
        """``model_stiffness`` by position."""
        rows = self._rows("SELECT * FROM model_stiffness ORDER BY position")
        return [record_of(ModelStiffnessRecord, r) for r in rows]

    def model_fit_rows(self) -> list[ModelFitRecord]:
        """Every ``model_fit`` (the stiffness fit, the static-error fit)."""
        return [record_of(ModelFitRecord, r) for r in self._rows("SELECT * FROM model_fit")]

    def model_fit(self, name: str) -> ModelFitRecord | None:
        """The ``model_fit`` called ``name`` ("stiffness" or "static_error"), if any."""
        rows = self._rows("SELECT * FROM model_fit WHERE name=?", (name,))
        return record_of(ModelFitRecord, rows[0]) if rows else None

    # --------------------------------------------------------------- sensors
    def delete_recordings_not_in(self, recordings: list[str]) -> None:
        """Remove the results of the recordings not listed (no longer in the spec)."""
        with self.transaction():
            for r in self._rows("SELECT recording FROM sensor_results"):
                if r["recording"] not in recordings:
                    self.conn.execute("DELETE FROM sensor_results WHERE recording=?", (r["recording"],))

    def sensor_result(self, recording: str) -> SensorResultRecord | None:
        """The ``sensor_results`` of a recording, if any."""
        rows = self._rows("SELECT * FROM sensor_results WHERE recording=?", (recording,))
        return record_of(SensorResultRecord, rows[0]) if rows else None

    def sensor_result_rows(self) -> list[SensorResultRecord]:
        """Every ``sensor_results``, in the order they were written."""
        return [
            record_of(SensorResultRecord, r)
            for r in self._rows("SELECT * FROM sensor_results ORDER BY rowid")
        ]

    def save_sensor_result(self, row: dict[str, Any]) -> None:
        """Store (replace) one recording's result."""
        with self.transaction():
            self._upsert("sensor_results", row)

    def set_recording_place(self, recording: str, point: str | None, direction: str) -> None:
        """Correct where a recording was measured (``point`` as JSON text) without analysing it again."""
        with self.transaction():
            self.conn.execute(
                "UPDATE sensor_results SET point=?, direction=? WHERE recording=?",
                (point, direction, recording),
            )

    def save_model_static_errors(self, fit: dict[str, Any], recordings: list[dict[str, Any]]) -> None:
        """Store a model fit to the static errors and the model's static error per recording.

        The ``model_static_error`` rows are replaced as a whole, in one transaction.
        """
        with self.transaction():
            self._upsert("model_fit", fit)
            self.conn.execute("DELETE FROM model_static_error")
            for row in recordings:
                self._upsert("model_static_error", row)

    def model_static_errors(self) -> dict[str, float | None]:
        """The model's static error per recording, mm (None where the model has none)."""
        return {r["recording"]: r["predicted_mm"] for r in self._rows("SELECT * FROM model_static_error")}


def _guarded(method):
    """A ``Store`` method whose SQLite errors about the file (damaged, locked, read-only, full)
    are an InputError naming it; other SQLite errors (a wrong statement: a bug) pass."""

    @functools.wraps(method)
    def call(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except (sqlite3.OperationalError, sqlite3.DatabaseError) as e:
            if type(e) not in (sqlite3.OperationalError, sqlite3.DatabaseError):
                raise
            raise self._input_error(e) from None
        except UnicodeDecodeError as e:  # a text column holding bytes that are not UTF-8
            raise self._input_error(sqlite3.DatabaseError(f"damaged text in a table ({e.reason})")) from None

    return call


for _name, _method in list(vars(Store).items()):
    if not _name.startswith("_") and _name not in ("close", "transaction") and callable(_method):
        setattr(Store, _name, _guarded(_method))


def _move_away(path: Path, what: str) -> InputError:
    return InputError(
        f"{what}; move it away (nothing was changed in it: stiffmap never deletes it) and run again",
        source=str(path),
    )


def _check_owner(conn: sqlite3.Connection, path: Path) -> None:
    """InputError unless the database is stiffmap's, or empty: checked before anything is written.

    Stiffmap's holds a ``meta`` table with its schema version and no object of another
    program's (table, view, trigger, index of a table that is not stiffmap's). An empty SQLite
    file (no object at all) is taken: nothing in it can be lost.
    """
    objects = [
        (r[0], r[1], r[2])
        for r in conn.execute("SELECT type, name, tbl_name FROM sqlite_master")
        if not str(r[1]).startswith("sqlite_")
    ]
    if not objects:
        return
    ours = set(_columns())
    foreign = [f"{kind} {name!r}" for kind, name, table in objects if table not in ours]
    if foreign:
        raise _move_away(
            path,
            f"not a stiffmap results database: it holds {', '.join(foreign[:3])}"
            f"{' ...' if len(foreign) > 3 else ''} (another program's file named {DB_NAME}?)",
        )
    tables = {name for kind, name, _ in objects if kind == "table"}
    added = {c for cols in _ADDED_COLUMNS.values() for c in cols}
    for table in sorted(tables):
        have = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        ours = set(_columns()[table])
        need = {c for c in ours if (table, c) not in added}
        if not need <= have <= ours:
            odd = sorted(have - ours) or sorted(need - have)
            raise _move_away(
                path,
                f"not a stiffmap results database: its table {table!r} has other columns than "
                f"stiffmap's ({', '.join(odd)})",
            )
    row = None
    if "meta" in tables:
        row = conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
    if row is None:
        raise _move_away(
            path,
            "not a stiffmap results database: it has tables but no stiffmap schema version "
            "(another program's file, or one edited by hand)",
        )
    if str(row[0]) not in {str(v) for v in range(1, SCHEMA_VERSION + 1)}:
        raise _move_away(
            path, f"database schema {str(row[0])[:20]!r} but this stiffmap uses {SCHEMA_VERSION}"
        )


#: The JSON columns stiffmap reads back as numbers: per table, the rows that hold them (an SQL
#: condition), the key naming a row, and each column's kind (:func:`_value_problem`); "!" after
#: a kind: never NULL in those rows.
_VALUES: tuple[tuple[str, str, str, dict[str, str]], ...] = (
    (
        "stiffness",
        "status = 'ok'",
        "position",
        {
            "K": "matrix!",
            "K_std": "sigmas",
            "K_cov": "cov",
            "K_cov_calibration": "cov",
            "eigenvalues": "vector",
            "residual_rms": "any",
        },
    ),
    ("model_stiffness", "1", "position", {"K": "matrix"}),
    ("model_stiffness", "valid = 1", "position", {"K": "matrix!"}),
    ("model_fit", "status = 'ok'", "name", {"params": "numbers!", "std": "sigma numbers", "cov": "cov"}),
    (
        "displacements",
        "status = 'ok'",
        "position, load, repeat",
        {"d": "displacement!", "cov": "displacement cov", "cov_calibration": "displacement cov"},
    ),
    (
        "measurements",
        "status = 'ok'",
        "image",
        {
            "mobile2cam": "pose",
            "fixed2cam": "pose",
            "mobile_cov": "cov",
            "fixed_cov": "cov",
        },
    ),
)

#: What ``typeof()`` may give in a column of each declared type (another is a damaged file:
#: bytes in a text column, text in a number's).
_TYPES = {"TEXT": ("text", "null"), "REAL": ("real", "integer", "null"), "INTEGER": ("integer", "null")}


#: Databases whose values this process checked or wrote, with the state their files were left in.
_TRUSTED: dict[Path, tuple] = {}


def _file_state(path: Path) -> tuple:
    """(size, mtime) of the database and its WAL file: any change by another process shows in it."""
    out = []
    for p in (path, path.with_name(path.name + "-wal")):
        try:
            st = p.stat()
            out.append((st.st_size, st.st_mtime_ns))
        except OSError:
            out.append(None)
    return tuple(out)


def _check_values(conn: sqlite3.Connection, path: Path) -> None:
    """InputError naming the table, row and column of the first stored value that is not what
    stiffmap writes there (a NULL, NaN or 2x2 K of a measured position, an edited model row)."""
    _check_types(conn, path)
    dims: dict[str, int] = {}  # the size of K, the same in every table
    for table, where, key, columns in _VALUES:
        keys = [k.strip() for k in key.split(",")]
        for r in conn.execute(f"SELECT {key}, {', '.join(columns)} FROM {table} WHERE {where}"):
            for col, kind, text in zip(columns, columns.values(), r[len(keys) :], strict=True):
                what = _value_problem(text, kind, dims)
                if what is not None:
                    row = ", ".join(f"{k} {v}" for k, v in zip(keys, r, strict=False))
                    raise _move_away(path, f"damaged or edited: table {table!r}, {row}: {col} {what}")


def _check_types(conn: sqlite3.Connection, path: Path) -> None:
    """InputError naming the first value whose SQLite type is not its column's (one scan per table)."""
    for table in _columns():
        cols = [(r[1], str(r[2]).upper()) for r in conn.execute(f"PRAGMA table_info({table})")]
        cols = [(c, t) for c, t in cols if t in _TYPES]
        odd = " OR ".join(f"typeof({c}) NOT IN ({', '.join(map(repr, _TYPES[t]))})" for c, t in cols)
        row = conn.execute(f"SELECT rowid, * FROM {table} WHERE {odd} LIMIT 1").fetchone() if odd else None
        if row is not None:
            col, declared = next((c, t) for c, t in cols if _sql_type(row[c]) not in _TYPES[t])
            raise _move_away(
                path,
                f"damaged or edited: table {table!r}, row {row[0]}: {col} holds {_sql_type(row[col])} "
                f"where {_TYPES_SAID[declared]} belongs",
            )


_TYPES_SAID = {"TEXT": "text", "REAL": "a number", "INTEGER": "an integer"}


def _sql_type(v: Any) -> str:
    """The ``typeof()`` of a value as sqlite3 returns it."""
    return {bytes: "blob", str: "text", float: "real", int: "integer", type(None): "null"}.get(type(v), "?")


def _value_problem(text: Any, kind: str, dims: dict[str, int]) -> str | None:
    """What is wrong with one stored value of ``kind``, or None (see :data:`_VALUES`)."""
    required = kind.endswith("!")
    kind = kind.rstrip("!")
    if text is None:
        return "is NULL where a value belongs" if required else None
    if kind == "any":
        return None
    try:
        v = json.loads(text)
    except (ValueError, TypeError, RecursionError):
        return f"is not JSON ({str(text)[:40]!r})"
    if kind.endswith("numbers"):
        ok = isinstance(v, dict) and all(
            isinstance(x, (int, float))
            and not isinstance(x, bool)
            and (np.isfinite(x) or kind != "numbers")
            or (x is None and kind != "numbers")
            for x in v.values()
        )
        return None if ok else f"is not an object of parameter values ({str(text)[:60]})"
    try:
        a = np.array(v, dtype=float)
    except (ValueError, TypeError, OverflowError):
        return f"is not an array of numbers ({str(text)[:60]})"
    return _array_problem(a, kind, dims, str(text)[:60])


def _array_problem(a: np.ndarray, kind: str, dims: dict[str, int], text: str) -> str | None:
    """What is wrong with a stored array of ``kind`` (sizes agreeing across rows through ``dims``)."""
    square = a.ndim == 2 and a.shape[0] == a.shape[1] and a.size > 0
    if kind == "pose":
        good = a.shape == (4, 4) and bool(np.all(np.isfinite(a)))
        return None if good else f"is not a 4x4 transform ({text})"
    if kind in ("matrix", "sigmas"):
        d = dims.setdefault("K", a.shape[0] if square else -1)
        if not square:
            return f"is not a square matrix ({text})"
        if a.shape[0] != d:
            return f"is {a.shape[0]}x{a.shape[0]} where the stiffness matrices are {d}x{d} ({text})"
        if kind == "matrix" and not np.all(np.isfinite(a)):
            return f"holds NaN or infinite entries where the stiffness is measured ({text})"
        if kind == "sigmas" and np.any(a < 0):
            return f"holds negative standard deviations ({text})"
        return None
    if kind == "displacement":
        good = a.ndim == 1 and a.size in (3, 6) and bool(np.all(np.isfinite(a)))
        dims["d"] = a.size
        return None if good else f"is not a displacement (3 or 6 finite numbers: {text})"
    if kind == "cov":
        return None if square and not np.any(np.isinf(a)) else f"is not a square covariance ({text})"
    if kind == "displacement cov":
        n = dims.get("d", 0)
        good = a.shape == (n, n) and not np.any(np.isinf(a))
        return None if good else f"is not the {n}x{n} covariance of the displacement ({text})"
    good = a.ndim == 1 and a.size > 0 and bool(np.all(np.isfinite(a)))
    return None if good else f"is not a list of finite numbers ({text})"


@functools.cache
def _columns() -> dict[str, tuple[str, ...]]:
    """The columns of every table of the schema (from an in-memory database built with it)."""
    conn = sqlite3.connect(":memory:")
    try:
        conn.executescript(_SCHEMA)
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return {
            t: tuple(r[1] for r in conn.execute(f"PRAGMA table_info({t})"))
            for t in tables
            if not t.startswith("sqlite_")
        }
    finally:
        conn.close()


def remove_database(directory: str | Path) -> None:
    """Delete a campaign's results database (``stiffmap.db`` and its WAL files), if there is one."""
    for name in (DB_NAME, f"{DB_NAME}-wal", f"{DB_NAME}-shm"):
        p = Path(directory) / name
        if p.is_file():
            p.unlink()


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
