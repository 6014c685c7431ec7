"""Positions as a user gives them (a preset, a CSV file, a list) and a selection of them by number."""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.errors import InputError
from stiffmap.kinds import positions_from_text
from stiffmap.models.presets import paper48, prr3_points22, select_positions


def test_presets_files_and_lists(tmp_path):
    np.testing.assert_array_equal(positions_from_text("paper48", "delta"), paper48())
    np.testing.assert_array_equal(positions_from_text(" Points22", "3prr"), prr3_points22())
    f = tmp_path / "pos.csv"
    f.write_text("x,y,z\n0,0,-310\n100,-50,-250\n")
    np.testing.assert_array_equal(
        positions_from_text(str(f), "delta"), [[0, 0, -310], [100, -50, -250]]
    )  # mm
    np.testing.assert_array_equal(positions_from_text("400,270; 300,420;", "3prr"), [[400, 270], [300, 420]])


def test_what_is_not_a_position_is_named():
    with pytest.raises(ValueError, match="paper48: that preset is for the delta model, not 3prr"):
        positions_from_text("paper48", "3prr")
    with pytest.raises(ValueError) as e:
        positions_from_text("1,2", "delta")
    assert str(e.value) == (
        "'1,2': expected a preset (paper48), a CSV file with columns x, y, z (mm), "
        "or positions 'x,y,z;x,y,z' in mm for the delta robot"
    )
    for text in ("abc", "1,2;3,4,5", "0,0,nan", ""):
        with pytest.raises(ValueError, match="expected a preset"):
            positions_from_text(text, "delta")
    # A CSV file's problems name the file, as an InputError.
    with pytest.raises(InputError, match=r"nope\.csv: file not found"):
        positions_from_text("nope.csv", "3prr")


def test_select_positions_by_number():
    P = paper48()
    np.testing.assert_array_equal(select_positions(P, "48, 1,22"), P[[47, 0, 21]])
    assert select_positions(P, None) is P and select_positions(P, "") is P
    for bad in ("0,49", "49", "a", ",", "1.5"):
        with pytest.raises(ValueError, match="between 1 and 48"):
            select_positions(P, bad)
    with pytest.raises(ValueError, match="'1,2,1': position 1 is given more than once"):
        select_positions(P, "1,2,1")
