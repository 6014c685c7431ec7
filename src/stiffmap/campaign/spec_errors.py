"""Problems in a TOML file told in the file's terms: the key, its line, and "did you mean".

:func:`validation_message` turns a pydantic :class:`~pydantic.ValidationError`
raised on the content of a TOML text into one line,
``line N, key 'a.b': what is wrong`` for each problem (joined by "; "), so that
``campaign.toml`` mistakes point at the line to edit.
"""

from __future__ import annotations

import difflib
import re
from typing import Any

from pydantic import BaseModel, ValidationError

__all__ = ["validation_message"]


def _table_paths(text: str) -> list[tuple[int, tuple]]:
    """(line number, key path) of every ``key =`` line and table header in a TOML text."""
    out: list[tuple[int, tuple]] = []
    table: tuple = ()
    counters: dict[tuple, int] = {}
    header = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?")
    keyline = re.compile(r"^\s*([A-Za-z0-9_\-\"'.]+)\s*=")
    for i, line in enumerate(text.splitlines(), start=1):
        m = header.match(line)
        if m:
            parts = tuple(p.strip().strip("\"'") for p in m.group(2).split("."))
            if m.group(1) == "[[":
                counters[parts] = counters.get(parts, -1) + 1
                table = (*parts, counters[parts])
            else:
                table = parts
            out.append((i, table))
            continue
        m = keyline.match(line)
        if m:
            key = tuple(p.strip().strip("\"'") for p in m.group(1).split("."))
            out.append((i, table + key))
    return out


def _line_of(paths: list[tuple[int, tuple]], loc: tuple) -> int | None:
    best, best_len = None, -1
    for line, path in paths:
        n = 0
        for a, b in zip(path, loc, strict=False):
            if str(a) != str(b):
                break
            n += 1
        if n == len(path) and n > best_len:
            best, best_len = line, n
    return best


def _known_keys(model: type[BaseModel], loc: tuple) -> list[str]:
    """Names of the keys valid at the table ``loc`` of ``model`` (for 'did you mean')."""
    current: Any = model
    for part in loc:
        if isinstance(part, int):
            continue
        field = getattr(current, "model_fields", {}).get(part)
        if field is None:
            return []
        ann = field.annotation
        candidates = [ann, *getattr(ann, "__args__", ())]
        nxt = None
        for c in candidates:
            for cc in (c, *getattr(c, "__args__", ())):
                if isinstance(cc, type) and issubclass(cc, BaseModel):
                    nxt = cc
        if nxt is None:
            return []
        current = nxt
    return list(getattr(current, "model_fields", {}))


def _describe(err: dict, model: type[BaseModel]) -> str:
    kind = err["type"]
    loc = tuple(err["loc"])
    if kind == "extra_forbidden":
        known = _known_keys(model, loc[:-1])
        close = difflib.get_close_matches(str(loc[-1]), known, n=1)
        hint = (
            f" (did you mean {close[0]!r}?)"
            if close
            else (f" (expected one of {', '.join(known)})" if known else "")
        )
        return f"unknown key{hint}"
    if kind == "missing":
        return "missing key"
    msg = err["msg"]
    msg = msg.removeprefix("Value error, ")
    if "input" in err and kind not in ("model_type",) and not isinstance(err["input"], dict):
        shown = repr(err["input"])
        if len(shown) > 60:
            shown = shown[:57] + "..."
        msg = f"{msg} (got {shown})"
    return msg


def validation_message(error: ValidationError, text: str, model: type[BaseModel]) -> str:
    """Every problem of ``error`` as ``line N, key 'a.b': what is wrong``, joined by "; ".

    Parameters
    ----------
    error : ValidationError
        Raised by ``model.model_validate`` on the content of ``text``.
    text : str
        The TOML text (for the line numbers).
    model : pydantic model class
        The validated model (for the keys it knows).
    """
    paths = _table_paths(text)
    msgs = []
    for err in error.errors():
        loc = tuple(x for x in err["loc"] if not (isinstance(x, str) and x.startswith("function-")))
        # pydantic adds union member names such as 'list[float]'; drop them.
        loc = tuple(
            x
            for x in loc
            if not (
                isinstance(x, str)
                and (
                    "[" in x or x in ("str", "float", "int", "bool") or re.fullmatch(r"[a-z]+(?:-[a-z]+)+", x)
                )
            )
        )
        text_msg = _describe(err, model)
        # A check across keys names its key at the start of its message ("a.b[2] = why"),
        # in full (from the top of the file), under the table it was raised for.
        m = re.match(r"([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\[(\d+)\])? = ", text_msg)
        if m:
            named = tuple(m.group(1).split(".")) + ((int(m.group(2)),) if m.group(2) else ())
            if [str(x) for x in named[: len(loc)]] == [str(x) for x in loc]:
                loc = named
                text_msg = text_msg[m.end() :]
        line = _line_of(paths, loc) if loc else None
        key = ".".join(str(x) for x in loc) if loc else "(top level)"
        where = f"line {line}, " if line else ""
        msgs.append(f"{where}key {key!r}: {text_msg}")
    # One line per campaign: the problems joined.
    return "; ".join(dict.fromkeys(msgs))
