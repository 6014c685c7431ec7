"""Tables that fit a terminal: at 80 or 100 columns a table wraps, splits or stacks, never cuts
a number (issue 26, item 4: "-0.88549…", "calibrati…" at 80-100 columns).

:func:`stiffmap.cli.common.fit_table` is the one home of this; the consoles of the CLI pass
every table they print through it. Here: tables drawn at random (numbers of every size, words,
file names) at widths from 30 to 120, the three ways a table is made to fit, and a real command
at COLUMNS=80 in a subprocess. Every command's own tables are checked at 80 and 100 columns in
``tests/test_cli_table_commands.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.cli_process import run_in_process, run_stiffmap
from helpers.table_width import NUMBER, assert_fits, numbers, rendered
from rich.table import Table

from stiffmap.loads import forces_matrix, paper9
from stiffmap.textfmt import fmt, fmt_pm


def _random_table(rng: np.random.Generator, n_cols: int, n_rows: int, header: bool) -> Table:
    t = Table(title=f"random table, {n_cols} columns" if rng.random() < 0.7 else None, show_header=header)
    kinds = rng.choice(["number", "pm", "words", "path"], size=n_cols)
    for j, kind in enumerate(kinds):
        t.add_column(
            f"column {j} ({kind})" if header else "",
            overflow="fold" if kind == "path" else "ellipsis",
            justify="right" if kind == "number" else "left",
        )
    for _ in range(n_rows):
        row = []
        for kind in kinds:
            x = rng.normal(scale=10.0 ** rng.integers(-6, 6))
            if kind == "number":
                row.append(fmt(x))
            elif kind == "pm":
                row.append(fmt_pm(x, abs(x) * rng.random()))
            elif kind == "words":
                row.append(" ".join(rng.choice(["calibration", "corner", "pose", "kept"], size=3)))
            else:
                row.append(f"/data/campaign_{rng.integers(1000)}/images/position_{rng.integers(99)}.png")
        t.add_row(*row)
    return t


@pytest.mark.parametrize("seed", range(12))
def test_random_tables_fit_every_width_with_every_number_whole(seed):
    rng = np.random.default_rng(seed)
    table = _random_table(rng, int(rng.integers(1, 12)), int(rng.integers(1, 6)), bool(rng.random() < 0.8))
    for width in (30, 50, 80, 100, 120):
        assert_fits(table, width)


def _delta_like() -> Table:
    """Ten numeric columns and a status, as ``stiffmap model delta`` prints (too wide for 80)."""
    t = Table(title="positions")
    for name in ("#", "x (mm)", "y (mm)", "z (mm)", "ux (mm)", "uy (mm)", "uz (mm)", "det K", "k_min (N/mm)"):
        t.add_column(name, justify="right")
    t.add_column("status")
    rng = np.random.default_rng(3)
    for i in range(6):
        t.add_row(str(i + 1), *(fmt(v) for v in rng.normal(scale=[200, 200, 300, 1, 1, 1, 500, 3])), "ok")
    return t


def test_a_wide_table_is_split_into_groups_of_columns_keyed_by_its_first():
    t = _delta_like()
    text = assert_fits(t, 80)
    headers = [ln for ln in text.splitlines() if "#" in ln]
    assert len(headers) == 2, text  # two groups, each with the rows' number
    assert "positions (continued)" in text
    # Every row number appears once per group.
    first_col = [ln.split("│")[1].strip() for ln in text.splitlines() if ln.startswith("│")]
    assert sorted(first_col) == sorted([str(i) for i in range(1, 7)] * 2)
    # As it is at 200 columns: one table.
    assert rendered(t, 200).count("#") == 1


def test_cells_wrap_at_spaces_when_the_words_fit():
    t = Table(show_header=False)
    for _ in range(3):
        t.add_column()
    t.add_row(fmt_pm(-0.885494, 0.0012345), fmt_pm(12.34567, 0.5), fmt_pm(1.2e-5, 3e-7))
    text = assert_fits(t, 30)
    assert "-0.88549" in text and "1.2e-05" in text
    assert sum(1 for ln in text.splitlines() if "±" in ln) >= 1
    assert rendered(t, 30).count("┌") == 1  # still one table


def test_a_table_too_narrow_for_its_columns_stacks_its_rows():
    t = Table("image", "fx (px)", "fy (px)", "reason")
    t.add_row("Image1.tif", fmt(657.4627), fmt(657.9512), "used")
    t.add_row("Image2.tif", fmt(-1.25e-4), fmt(3.5), "board not found")
    text = assert_fits(t, 24)
    assert text.count("fx") == 2 and text.count("reason") == 2  # once per row
    assert "657.46" in text and "-0.000125" in text


def test_json_and_plain_numbers_regex():
    assert NUMBER.findall("a -0.88549 ± 1.2e-05, 66.6667 x2 13x12") == ["-0.88549", "1.2e-05", "66.6667"]
    assert numbers("1 1 2")["1"] == 2


def test_identify_on_a_30_column_terminal(tmp_path, monkeypatch, capsys):
    """The real command honours COLUMNS (the width of the user's terminal) and cuts nothing."""
    F = forces_matrix(paper9())
    K = np.array([[3.1, 0.4, 0.2], [0.4, 2.2, -0.3], [0.2, -0.3, 5.0]])
    D = np.linalg.solve(K, F) + np.random.default_rng(1).normal(scale=1e-3, size=F.shape)
    (tmp_path / "f.csv").write_text("fx,fy,fz\n" + "\n".join(",".join(map(str, r)) for r in F.T) + "\n")
    (tmp_path / "d.csv").write_text("dx,dy,dz\n" + "\n".join(",".join(map(str, r)) for r in D.T) + "\n")
    files = [tmp_path / "f.csv", tmp_path / "d.csv"]
    narrow = run_stiffmap("identify", *files, columns=30)
    status, wide, _ = run_in_process(["identify", *files], monkeypatch, capsys)
    assert narrow.returncode == status == 0, narrow.stderr
    assert "…" not in narrow.stdout
    assert not numbers(wide) - numbers(narrow.stdout)
    table_lines = [ln for ln in narrow.stdout.splitlines() if ln[:1] in "│┃┏┡└┌├"]
    assert table_lines and max(len(ln) for ln in table_lines) <= 30
