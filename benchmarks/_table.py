"""Print a benchmark table and save it as Markdown under benchmarks/results/ (or write a whole page)."""

from __future__ import annotations

import datetime
import platform
from collections.abc import Sequence
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def markdown(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    cells = [[str(c) for c in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    line = lambda r: "| " + " | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) + " |"  # noqa: E731
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    return "\n".join([line(cells[0]), sep, *(line(r) for r in cells[1:])])


def save(
    name: str, title: str, headers: Sequence[str], rows: Sequence[Sequence[object]], notes: str = ""
) -> Path:
    """Print the table and write ``results/<name>.md`` (with the machine and date)."""
    table = markdown(headers, rows)
    stamp = f"{datetime.date.today().isoformat()}, Python {platform.python_version()}, {platform.machine()}"
    text = (
        f"# {title}\n\n{notes.strip()}\n\n{table}\n\n_{stamp}_\n"
        if notes
        else f"# {title}\n\n{table}\n\n_{stamp}_\n"
    )
    print(text)
    return write(RESULTS / f"{name}.md", text)


def write(path: str | Path, text: str) -> Path:
    """Write a result page (UTF-8, creating its folder) and say where."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    print(f"saved {path}")
    return path
