"""Frozen records of numpy arrays: checking their fields, and their JSON round trip.

The report's data contract (:mod:`stiffmap.report.data`) is made of frozen
dataclasses whose ``__post_init__`` converts and checks each field with the
``set_*`` functions here (read-only float64 arrays of a named shape, lists of
strings, finite numbers); :func:`dump_record` and :func:`load_record` turn a record
into plain JSON values and back, with errors that name the key path.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence, Set
from dataclasses import MISSING, fields
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["set_array", "set_optional_array", "set_strings", "set_float", "dump_record", "load_record"]


def set_array(
    obj,
    name: str,
    value,
    shape: tuple,
    dims: dict[str, int],
    *,
    finite: bool = False,
    limit: float | None = None,
) -> None:
    """Convert ``obj.name`` to a read-only float64 array of ``shape`` (ints or symbols).

    ``limit``: the largest plausible magnitude of an entry (a physical bound of what the
    field holds); beyond it the value is refused, as a broken file rather than a number
    to draw.
    """
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers, got {type(value).__name__}") from None
    except OverflowError:  # an integer beyond float64
        raise ValueError(f"{name}: a number beyond the range of floating point") from None
    want = "(" + ", ".join(str(s) for s in shape) + (",)" if len(shape) == 1 else ")")
    if a.ndim != len(shape):
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    for s, k in zip(shape, a.shape, strict=True):
        if isinstance(s, int):
            if k != s:
                raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
        elif s in dims and dims[s] != k:
            raise ValueError(f"{name}: expected shape {want} with {s} = {dims[s]}, got {a.shape}")
        else:
            dims[s] = k
    if np.any(np.isinf(a)):
        raise ValueError(f"{name}: infinite values")
    if finite and np.any(np.isnan(a)):
        raise ValueError(f"{name}: NaN values where numbers are required")
    if limit is not None and np.any(np.abs(a) > limit):
        v = float(a[np.abs(a) > limit].ravel()[0])
        raise ValueError(f"{name}: {v:.6g} is beyond +-{limit:g}: not a plausible value")
    a.setflags(write=False)
    object.__setattr__(obj, name, a)


def set_optional_array(obj, name: str, value, shape: tuple, dims: dict[str, int], **kw) -> None:
    if value is None:
        object.__setattr__(obj, name, None)
    else:
        set_array(obj, name, value, shape, dims, **kw)


def set_strings(obj, name: str, value, n: int | None, *, default: Sequence[str] | None = None) -> None:
    if value is None:
        value = default
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ValueError(f"{name}: expected a list of strings, got {type(value).__name__}")
    t = tuple(value)
    if not all(isinstance(s, str) for s in t):
        raise ValueError(f"{name}: expected a list of strings")
    if n is not None and len(t) != n:
        raise ValueError(f"{name}: expected {n} entries, got {len(t)}")
    object.__setattr__(obj, name, t)


def set_float(obj, name: str, value, *, positive: bool = False, allow_nan: bool = False) -> None:
    if value is None and allow_nan:
        value = math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond float64
        raise ValueError(f"{name}: expected a finite number, got an integer beyond floating point") from None
    if math.isinf(v) or (math.isnan(v) and not allow_nan):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if positive and not v > 0:
        raise ValueError(f"{name}: expected a positive number, got {value!r}")
    object.__setattr__(obj, name, v)


def dump_record(obj) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if hasattr(v, "__dataclass_fields__"):
            v = dump_record(v)
        elif isinstance(v, tuple) and v and hasattr(v[0], "__dataclass_fields__"):
            v = [dump_record(x) for x in v]
        out[f.name] = v
    return out


def _nan_from_null(v):
    """JSON ``null`` (as written for NaN) back to NaN, recursively in lists."""
    if v is None:
        return math.nan
    if isinstance(v, list):
        return [_nan_from_null(x) for x in v]
    return v


def load_record(
    cls: type,
    data: Any,
    path: str,
    source: str | None,
    *,
    nested: Mapping[tuple[type, str], type],
    nested_lists: Mapping[tuple[type, str], type],
    array_fields: Set[str],
):
    """Build a ``cls`` record from its JSON object, or an InputError naming the key path.

    ``nested`` / ``nested_lists`` give the record type of each (class, field) holding a
    record / a list of records; ``array_fields`` the fields whose ``null`` entries mean NaN.
    """
    kw = dict(nested=nested, nested_lists=nested_lists, array_fields=array_fields)
    where = path or "top level"
    if not isinstance(data, Mapping):
        raise InputError(f"key {where!r}: expected an object, got {type(data).__name__}", source=source)
    names = {f.name: f for f in fields(cls)}
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise InputError(
            f"key {(path + '.' if path else '') + unknown[0]!r}: unknown key "
            f"(expected one of {', '.join(names)})",
            source=source,
        )
    kwargs: dict[str, Any] = {}
    for name, f in names.items():
        key = f"{path}.{name}" if path else name
        if name not in data:
            if f.default is MISSING and f.default_factory is MISSING:
                raise InputError(f"key {key!r} is missing", source=source)
            continue
        v = data[name]
        if (cls, name) in nested:
            v = None if v is None else load_record(nested[(cls, name)], v, key, source, **kw)
        elif (cls, name) in nested_lists:
            if not isinstance(v, list):
                raise InputError(f"key {key!r}: expected a list, got {type(v).__name__}", source=source)
            v = tuple(
                load_record(nested_lists[(cls, name)], x, f"{key}[{i}]", source, **kw)
                for i, x in enumerate(v)
            )
        elif name in array_fields and v is not None:
            v = _nan_from_null(v)
        elif name in ("std", "value", "reference_load_n") and v is None:
            v = math.nan
        kwargs[name] = v
    try:
        return cls(**kwargs)
    except InputError:
        raise
    except (ValueError, TypeError, OverflowError) as e:
        msg = str(e)
        # The record's own message starts with the field name; prefix the path.
        raise InputError(f"key {(path + '.' if path else '')}{msg}", source=source) from None
