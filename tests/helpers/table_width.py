"""Checks that a table printed on a narrow terminal lost nothing: no line too long, no ``…``,
every number of the wide rendering whole in the narrow one."""

from __future__ import annotations

import io
import re
from collections import Counter

from rich.cells import cell_len
from rich.console import Console
from rich.table import Table

from stiffmap.cli.common import fit_table

#: A number as the CLI prints it (``-0.88549``, ``1.2e-05``, ``66.6667``), delimited by
#: anything that cannot continue it.
NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![\w.])")


def rendered(table: Table, width: int) -> str:
    """What :data:`stiffmap.cli.common.out` prints for ``table`` on a ``width``-column terminal."""
    console = Console(file=io.StringIO(), width=width, highlight=False, soft_wrap=True, no_color=True)
    console.print(fit_table(table, console))
    return console.file.getvalue()


def numbers(text: str) -> Counter:
    """The numbers of a text, with how often each appears."""
    return Counter(NUMBER.findall(text))


def assert_fits(table: Table, width: int, *, wide: int = 400) -> str:
    """``table`` at ``width`` columns: every line fits, nothing is cut, every number of its
    ``wide`` rendering appears whole, at least as often (groups of columns repeat the rows' key)."""
    narrow, full = rendered(table, width), rendered(table, wide)
    assert "…" not in full, f"cut even at {wide} columns:\n{full}"
    assert "…" not in narrow, f"cut at {width} columns:\n{narrow}"
    too_long = [ln for ln in narrow.splitlines() if cell_len(ln) > width]
    assert not too_long, f"lines wider than {width} columns:\n" + "\n".join(too_long)
    missing = numbers(full) - numbers(narrow)
    assert not missing, f"numbers cut or lost at {width} columns: {sorted(missing)}\n{narrow}"
    return narrow
