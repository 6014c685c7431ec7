"""Reading user tables and writing results safely.

- :func:`read_csv_columns` reads a CSV with a header into float columns and
  raises :class:`~stiffmap.errors.InputError` naming the file, the row (as the
  line number in the file) and the column for every problem: missing file,
  not UTF-8 text, missing column, empty table, a row with more cells than the
  header, a cell that is not a number, NaN, a field too long for a table.
- :func:`read_text_file` reads a UTF-8 text file, refusing one that is not
  (UTF-16, Latin-1, binary) instead of reading garbage.
- :func:`atomic_write_text` / :func:`atomic_write_bytes` write through a
  temporary file in the same directory and ``os.replace``, so a reader never
  sees a half-written result and an interrupted run leaves the old file.
- :func:`read_json` reads a JSON file, raising :class:`~stiffmap.errors.InputError`
  naming the file when it is missing, unreadable or not valid JSON.
- :func:`to_jsonable` turns numpy arrays and floats into JSON values
  (NaN and infinities become ``null``).
"""

from __future__ import annotations

import csv
import difflib
import json
import math
import os
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = [
    "Table",
    "read_csv_columns",
    "read_text_file",
    "read_json",
    "atomic_write_text",
    "atomic_write_bytes",
    "to_jsonable",
    "dumps_json",
    "ALLOW_OUTSIDE_OPTION",
    "leaves_directory",
    "no_such_path",
    "parse_number",
]


def parse_number(text: str) -> float:
    """``float(text)`` without what Python's float takes that no file, controller or person means
    as a number: underscores between digits (``1_5`` would be 15) and digits of other scripts
    (``١٢٣``, ``５``). ValueError for those, as for any text float refuses."""
    if "_" in text or not text.isascii():
        raise ValueError(f"{text!r} is not a number")
    return float(text)


def no_such_path(path: str | os.PathLike) -> str:
    """What to say of a path that does not exist: ``no such file or folder``, and the closest
    name beside it when there is one (a misspelt folder: ``did you mean 'calib_example'?``)."""
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    hint = ""
    try:
        if p.name and parent.is_dir():
            names = [q.name for q in parent.iterdir()]
            close = difflib.get_close_matches(p.name, names, n=1, cutoff=0.75)
            hint = f" (did you mean {str(parent / close[0])!r}?)" if close else ""
        elif not parent.exists():
            hint = f" (the folder {str(parent)!r} does not exist either)"
    except OSError:
        pass
    return f"no such file or folder{hint}"


@dataclass(frozen=True)
class Table:
    """Numeric columns of a CSV file.

    Attributes
    ----------
    path : str
    columns : dict of str to ndarray, shape (n,)
    lines : ndarray of int, shape (n,)
        The 1-based line number in the file of each data row (for messages).
    text : dict of str to list of str
        Raw text of the columns that were read as text.
    """

    path: str
    columns: dict[str, np.ndarray]
    lines: np.ndarray
    text: dict[str, list[str]]

    def __len__(self) -> int:
        return int(self.lines.size)

    def has(self, name: str) -> bool:
        return name in self.columns

    def stack(self, names: Sequence[str]) -> np.ndarray:
        """Columns as rows of an array, shape (len(names), n)."""
        return np.stack([self.columns[c] for c in names])

    def check_magnitude(self, names: Iterable[str], limit: float, unit: str, what: str) -> None:
        """Refuse a cell of the columns ``names`` whose magnitude exceeds ``limit``.

        For physical plausibility at the boundary (a displacement of 1e308 mm is a broken
        file, not a measurement): an InputError ``line N, column 'x': 1e+308 mm is beyond
        +-LIMIT mm: not a plausible WHAT``. Columns not in the table are skipped.
        """
        for c in names:
            v = self.columns.get(c)
            if v is None:
                continue
            bad = np.flatnonzero(np.abs(v) > limit)
            if bad.size:
                i = int(bad[0])
                raise InputError(
                    f"line {self.lines[i]}, column {c!r}: {v[i]:.6g} {unit} is beyond +-{limit:g} {unit}: "
                    f"not a plausible {what}",
                    source=self.path,
                )


def sniff_delimiter(lines: Sequence[str]) -> str:
    """The field separator of a delimited text file: comma, tab or semicolon.

    Judged on the header (the first line that is neither blank nor a ``#``
    comment): the separator it holds most often, a comma when it holds none
    (a single column). DAQ software often writes tab-separated ``.txt`` files,
    and spreadsheets in many locales write ``;`` with decimal commas.
    """
    for line in lines:
        if line.strip() and not line.lstrip().startswith("#"):
            counts = {d: line.count(d) for d in (",", "\t", ";")}
            best = max(counts, key=lambda d: counts[d])
            return best if counts[best] > 0 else ","
    return ","


_SEPARATOR_NAMES = {",": "','", "\t": "tab", ";": "';'"}


def read_text_file(path: str | os.PathLike, what: str = "text file") -> str:
    """The text of a UTF-8 file (a leading byte-order mark dropped), or an InputError naming it.

    A file that is not UTF-8 (UTF-16, Latin-1 with accents, a binary file) is refused as
    such rather than read as garbage: its bytes are not decoded, or it holds NUL characters
    (UTF-16 text, binary data), which no text table holds.

    Raises
    ------
    InputError
        ``not UTF-8 text (...)``, ``cannot read: ...``; ``what`` names the expected kind of file.
    """
    p = Path(path)
    src = str(path)
    try:
        raw = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(
            f"not UTF-8 text ({e.reason} 0x{e.object[e.start]:02x} at byte {e.start}); "
            f"expected a {what} saved as UTF-8",
            source=src,
        ) from None
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", source=src) from None
    nul = raw.find("\x00")
    if nul >= 0:
        line = raw.count("\n", 0, nul) + 1
        raise InputError(
            f"not UTF-8 text: line {line} holds a NUL character (UTF-16 text, or a binary file?); "
            f"expected a {what} saved as UTF-8",
            source=src,
        )
    return raw


def _refuse_json(raw: str, required: Sequence[str], src: str) -> None:
    """InputError when a file given as a CSV table is JSON (an object or a list: ``{`` or ``[`` first)."""
    head = raw.lstrip("\ufeff \t\r\n")[:1]
    if head not in ("{", "["):
        return
    try:
        json.loads(raw)
        what = "is a JSON file"
    except (ValueError, RecursionError):
        what = f"looks like JSON (it begins with {head!r})"
    raise InputError(
        f"{what}, not a CSV table; expected a header row"
        f"{' with columns ' + ', '.join(required) if required else ''} and one row of numbers per line",
        source=src,
    )


def read_csv_columns(
    path: str | os.PathLike,
    required: Iterable[str],
    optional: Iterable[str] = (),
    *,
    text_columns: Iterable[str] = (),
    allow_nan: bool = False,
) -> Table:
    """Read named numeric columns from a CSV file with a header row.

    The separator may be a comma, a tab or a semicolon (found from the header);
    with a tab or a semicolon, a decimal comma (``1,25``) is read as well.

    Parameters
    ----------
    path : path-like
    required : iterable of str
        Columns that must be present (case-insensitive, surrounding spaces ignored).
    optional : iterable of str
        Columns read when present.
    text_columns : iterable of str
        Columns (required or optional) kept as text rather than parsed as numbers.
    allow_nan : bool
        Accept empty cells and ``nan`` (otherwise a clear error).

    Raises
    ------
    InputError
        Naming the file, and the line and column of the first bad cell.
    """
    p = Path(path)
    src = str(path)
    required = [c.strip().lower() for c in required]
    optional = [c.strip().lower() for c in optional]
    text_columns = {c.strip().lower() for c in text_columns}
    if not p.exists():
        raise InputError("file not found", source=src)
    if p.is_dir():
        raise InputError("is a directory, expected a CSV file", source=src)
    rows, delimiter = _csv_rows(p, src, required)
    start, header, wanted = _header(rows, required, optional, src)
    idx = {c: header.index(c) for c in wanted}
    data: dict[str, list[float]] = {c: [] for c in wanted if c not in text_columns}
    text: dict[str, list[str]] = {c: [] for c in wanted if c in text_columns}
    lines: list[int] = []
    for k in range(start + 1, len(rows)):
        row = rows[k]
        if not row or all(not cell.strip() for cell in row) or row[0].lstrip().startswith("#"):
            continue
        line = k + 1
        if len(row) > len(header) and any(cell.strip() for cell in row[len(header) :]):
            # A decimal comma in a comma-separated file, a separator in a cell, a shifted row:
            # reading the first cells would give wrong numbers.
            raise InputError(
                f"line {line}: {len(row)} cells but the header has {len(header)} columns "
                f"(separator {_SEPARATOR_NAMES[delimiter]}; a decimal comma in a comma-separated file?)",
                source=src,
            )
        for c in wanted:
            j = idx[c]
            cell = row[j].strip() if j < len(row) else ""
            if c in text_columns:
                text[c].append(cell)
            else:
                data[c].append(_number(cell, line, c, delimiter, allow_nan, src))
        lines.append(line)
    if not lines:
        raise InputError("no data rows after the header", source=src)
    return Table(src, {c: np.asarray(v, dtype=np.float64) for c, v in data.items()}, np.asarray(lines), text)


def _csv_rows(p: Path, src: str, required: list[str]) -> tuple[list[list[str]], str]:
    """The rows of a CSV file (not JSON) and its separator."""
    raw = read_text_file(p, "CSV file")
    _refuse_json(raw, required, src)
    lines_text = raw.splitlines()
    delimiter = sniff_delimiter(lines_text)
    reader = csv.reader(lines_text, delimiter=delimiter)
    try:
        return list(reader), delimiter
    except csv.Error as e:  # a field longer than the csv module's limit (131072 characters)
        raise InputError(f"line {reader.line_num}: not a table of numbers ({e})", source=src) from None


def _header(rows, required: list[str], optional: list[str], src: str) -> tuple[int, list[str], list[str]]:
    """The header's row (after leading blank and comment lines), its column names (lower case)
    and the columns wanted that it has; every required one, none twice."""
    start = 0
    while start < len(rows) and (not rows[start] or rows[start][0].lstrip().startswith("#")):
        start += 1
    if start >= len(rows):
        raise InputError(f"empty file; expected a header with columns {', '.join(required)}", source=src)
    header = [h.strip().lower() for h in rows[start]]
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(
            f"missing column{'s' if len(missing) > 1 else ''} {', '.join(repr(c) for c in missing)} "
            f"(header has {', '.join(repr(h) for h in header)})",
            source=src,
        )
    dup = {h for h in header if header.count(h) > 1 and h}
    if dup & set(required + optional):
        raise InputError(f"column {sorted(dup)[0]!r} appears more than once", source=src)
    return start, header, [c for c in required + optional if c in header]


def _number(cell: str, line: int, c: str, delimiter: str, allow_nan: bool, src: str) -> float:
    """The number in a (stripped) cell: a decimal comma read with ``;`` or tab separators; an
    empty cell or ``nan`` only with ``allow_nan``."""
    if cell == "" and not allow_nan:
        raise InputError(f"line {line}, column {c!r}: empty cell, expected a number", source=src)
    if delimiter != "," and "," in cell and "." not in cell:
        cell = cell.replace(",", ".")  # decimal comma (files written with ; or tab)
    try:
        v = parse_number(cell) if cell != "" else math.nan
    except ValueError:
        raise InputError(f"line {line}, column {c!r}: {cell!r} is not a number", source=src) from None
    if not math.isfinite(v) and not allow_nan:
        raise InputError(f"line {line}, column {c!r}: {cell!r} is not a finite number", source=src)
    return v


def read_json(path: str | os.PathLike, what: str = "file"):
    """Parse a UTF-8 JSON file.

    Parameters
    ----------
    path : path-like
    what : str
        What the file is, for the message when it is missing (``"camera file"``).

    Returns
    -------
    The parsed JSON value (dict, list, str, number, bool or None).

    Raises
    ------
    InputError
        Naming the file: ``"<what> not found"``, ``"cannot read: ..."`` or
        ``"not valid JSON (line L, column C: ...)"``.
    """
    p = Path(path)
    src = str(path)
    if not p.is_file():
        raise InputError(f"{what} not found", source=src)
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})", source=src) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read: {e}", source=src) from None
    except RecursionError:
        raise InputError("not a usable JSON file: nested too deeply", source=src) from None
    except ValueError:  # an integer of thousands of digits
        raise InputError("not a usable JSON file: a number has thousands of digits", source=src) from None


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file + ``os.replace``).

    Raises
    ------
    InputError
        ``path`` is a directory, or its folder cannot be made (a file of that
        name is in the way) or written to.
    """
    p = Path(path)
    src = str(path)
    if p.is_dir():
        raise InputError("is a directory; expected the path of a file to write", source=src)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        msg = "cannot make its folder: a file is in the way of the folder path"
        raise InputError(msg, source=src) from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    except OSError as e:
        raise InputError(f"cannot write in {p.parent}: {e.strerror}", source=src) from None
    try:
        # mkstemp creates the file 0600; give it the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def json_close(a, b, rtol: float = 1e-9) -> bool:
    """Whether two JSON values are equal, numbers within ``rtol`` (relative)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(json_close(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(json_close(x, y, rtol) for x, y in zip(a, b, strict=True))
    num = (int, float)
    if isinstance(a, num) and isinstance(b, num) and not isinstance(a, bool) and not isinstance(b, bool):
        return math.isclose(a, b, rel_tol=rtol, abs_tol=1e-300)
    return a == b


def _same_result(old: bytes, new: bytes) -> bool:
    if old == new:
        return True
    try:  # JSON results that differ only in the last digits (threaded solvers) are the same
        return json_close(json.loads(old), json.loads(new))
    except (ValueError, UnicodeDecodeError):
        return False


def replace_keeping_previous(path: str | os.PathLike, text: str) -> Path | None:
    """Write ``text`` to ``path`` atomically; a different earlier file is kept as ``<name>.bak``.

    For results a command writes to a fixed default name (``camera.json``):
    running it again on other data must not silently destroy the earlier result.
    JSON files whose numbers agree to 1e-9 (relative) count as the same.

    Returns
    -------
    Path or None
        The backup written, or None (no earlier file, or the same content).
    """
    p = Path(path)
    data = text.encode("utf-8")
    backup = None
    if p.is_file():
        old = p.read_bytes()
        if not _same_result(old, data):
            backup = p.with_name(p.name + ".bak")
            atomic_write_bytes(backup, old)
    atomic_write_bytes(p, data)
    return backup


def to_jsonable(obj):
    """Convert numpy values (recursively) to plain JSON values; NaN/inf become None."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def dumps_json(obj, *, indent: int | None = 2, inline_numbers: bool = False) -> str:
    """JSON text of ``obj`` after :func:`to_jsonable`.

    With ``inline_numbers`` (and an ``indent``), a list of numbers is written on one line
    (a matrix: one row per line): a file of many coordinates stays a few times smaller and
    readable.
    """
    value = to_jsonable(obj)
    if inline_numbers and indent:
        return _inline_json(value, indent, 0)
    return json.dumps(value, indent=indent, allow_nan=False)


def _inline_json(v, indent: int, level: int) -> str:
    flat = isinstance(v, list) and all(x is None or isinstance(x, int | float) for x in v)
    if not isinstance(v, dict | list) or not v or flat:
        return json.dumps(v, allow_nan=False, separators=(", ", ": "))
    pad, end = " " * (indent * (level + 1)), " " * (indent * level)
    if isinstance(v, dict):
        items = [f"{pad}{json.dumps(k)}: {_inline_json(x, indent, level + 1)}" for k, x in v.items()]
        return "{\n" + ",\n".join(items) + "\n" + end + "}"
    return "[\n" + ",\n".join(f"{pad}{_inline_json(x, indent, level + 1)}" for x in v) + "\n" + end + "]"


#: The command-line option that lets a campaign.toml or an index file name files outside its directory.
ALLOW_OUTSIDE_OPTION = "--allow-outside-paths"


def leaves_directory(root: str | os.PathLike, name: str, cache: dict | None = None) -> str | None:
    """How the file name ``name`` (relative to ``root``) leads outside ``root``; None if it stays in.

    ``..`` and symbolic links are resolved first: ``a/../b`` stays inside, a link to
    elsewhere does not.

    Parameters
    ----------
    root : path-like
    name : str
    cache : dict, optional
        Folders already resolved, for many names checked at once (a campaign's images):
        each folder is resolved once, each file only when it is a symbolic link.

    Returns
    -------
    str or None
        "is an absolute path", "goes up with '..' (to TARGET)" or "leads through a
        symbolic link to TARGET"; None for a name inside ``root`` (or one that cannot be
        resolved at all, e.g. holding a NUL byte: reading it fails with its own message).
    """
    p = Path(name)
    if p.is_absolute() or p.drive or p.root:
        return "is an absolute path"
    cache = {} if cache is None else cache

    def resolved(folder: Path) -> Path:
        if folder not in cache:
            cache[folder] = folder.resolve()
        return cache[folder]

    try:
        base = resolved(Path(root))
        target = resolved(Path(root) / p.parent) / p.name
        if p.name in ("", ".", "..") or target.is_symlink():
            target = target.resolve()
    except (OSError, ValueError, RuntimeError):
        return None
    if target == base or target.is_relative_to(base):
        return None
    if ".." in p.parts:
        return f"goes up with '..' (to {target})"
    return f"leads through a symbolic link to {target}"
