"""Load designs as a user gives them: a preset's name or a CSV file, refused when they cannot determine K."""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.errors import DesignError, InputError
from stiffmap.loads import check_load_design, forces_matrix, load_design, paper9, read_loads_csv


@pytest.mark.parametrize(
    ("forces", "rank"),
    [
        ([[1.0, 0, 0], [2.0, 0, 0]], 1),  # one axis, two magnitudes
        ([[1.0, 0, 0], [0, 2.0, 0], [1.0, 1.0, 0]], 2),  # three loads in the xy plane
        ([[0, 0, -4.905], [0, 0, -1.962], [0, 0, -0.981]], 1),  # the paper's -z loads alone
    ],
)
def test_a_rank_deficient_design_is_refused_with_its_rank(forces, rank):
    with pytest.raises(DesignError) as e:
        check_load_design(forces, source="loads.csv")
    assert str(e.value) == (
        f"loads.csv: the {len(forces)} load(s) span {rank} independent direction(s); 3 are needed "
        "to identify a 3x3 stiffness (add loads along other axes)"
    )
    assert isinstance(e.value, InputError)  # the command line prints it as one line


def test_a_design_of_three_directions_passes():
    check_load_design(forces_matrix(paper9()).T)  # N
    # Rank is judged relative to the largest force: a 1 mN load among 5 N ones still counts.
    check_load_design([[5.0, 0, 0], [0, 5.0, 0], [0, 0, 1e-3]])
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        check_load_design(np.zeros((0, 3)))


def test_read_loads_csv_labels_and_errors(tmp_path):
    f = tmp_path / "loads.csv"
    f.write_text("fx,fy,fz,label\n0,0,-4.905,0.5 kg down\n-2,0,0,\n0,3,0,3 N +y\n")
    loads = read_loads_csv(f)
    assert [ld.label for ld in loads] == ["0.5 kg down", "F = (-2, 0, 0) N", "3 N +y"]
    np.testing.assert_array_equal(forces_matrix(loads).T, [[0, 0, -4.905], [-2, 0, 0], [0, 3, 0]])  # N
    assert all(not np.any(ld.cov) for ld in loads)  # exact loads
    zero = tmp_path / "zero.csv"
    zero.write_text("fx,fy,fz\n1,0,0\n0,0,0\n0,0,1\n")
    with pytest.raises(InputError, match=r"zero.csv: line 3: the force is zero"):
        read_loads_csv(zero)
    flat = tmp_path / "flat.csv"
    flat.write_text("fx,fy,fz\n1,0,0\n2,0,0\n")
    with pytest.raises(DesignError, match=r"flat.csv: the 2 load\(s\) span 1 independent direction"):
        read_loads_csv(flat)


def test_load_design_takes_a_preset_or_a_file(tmp_path):
    np.testing.assert_array_equal(forces_matrix(load_design(" PAPER9 ", 9.81)), forces_matrix(paper9(g=9.81)))
    np.testing.assert_allclose(forces_matrix(load_design("paper9", 9.80665))[:, 0], [0, 0.5 * 9.80665, 0])
    f = tmp_path / "mine.csv"
    f.write_text("fx,fy,fz\n1,0,0\n0,1,0\n0,0,1\n")
    assert len(load_design(str(f))) == 3
    with pytest.raises(ValueError) as e:
        load_design("paper10")
    assert not isinstance(e.value, InputError)  # the command line puts the option's name in front
    assert str(e.value) == (
        "'paper10': expected a preset (paper9) or a CSV file with columns fx, fy, fz (N) and optionally label"
    )
