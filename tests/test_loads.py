"""Load cases: masses to forces, friction correction, the reference preset."""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.loads import (
    LoadCase,
    force_covariances,
    forces_matrix,
    load_from_mass,
    paper9,
    preset,
    scaled_loads,
    with_friction,
)
from stiffmap.units import G_STANDARD


def test_mass_to_force_uses_the_campaign_g():
    ld = load_from_mass(0.5, "-z")
    np.testing.assert_allclose(ld.force, [0, 0, -0.5 * G_STANDARD], rtol=1e-15)
    ld = load_from_mass(0.5, [1, 1, 0], g=9.81)
    np.testing.assert_allclose(ld.force, 0.5 * 9.81 * np.array([1, 1, 0]) / np.sqrt(2), rtol=1e-15)


def test_paper9_forces_are_table_ii():
    F = forces_matrix(paper9())
    assert F.shape == (3, 9)
    np.testing.assert_allclose(F[:, 0], [0, 4.905, 0], atol=1e-12)
    np.testing.assert_allclose(F[:, 1], [-4.905, 0, 0], atol=1e-12)
    np.testing.assert_allclose(F[:, 8], [0, 0, -0.981], atol=1e-12)
    np.testing.assert_allclose(forces_matrix(preset("paper9", g=G_STANDARD))[:, 0], [0, 0.5 * G_STANDARD, 0])


def test_friction_of_the_reference_experiment():
    # 28 g +- 8 g of friction on a 500 g load pulled along -x (the reference study, section 2.4).
    ld = with_friction(load_from_mass(0.5, "-x", g=9.81), 0.028, 0.008, g=9.81)
    np.testing.assert_allclose(ld.force, [-(0.5 - 0.028) * 9.81, 0, 0], rtol=1e-14)
    assert ld.cov[0, 0] == pytest.approx((0.008 * 9.81) ** 2, rel=1e-14)
    assert ld.cov[1, 1] == 0 and ld.cov[2, 2] == 0
    # Less than 6 % of the applied force, as the paper says.
    assert 0.028 / 0.5 < 0.06
    assert force_covariances([ld]).shape == (1, 3, 3)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: load_from_mass(-1, "x"), "positive"),
        (lambda: load_from_mass(1, "w"), "unknown direction"),
        (lambda: load_from_mass(1, [0, 0, 0]), "non-zero"),
        (lambda: with_friction(load_from_mass(0.1, "x"), 0.2), "not smaller"),
        (lambda: preset("paper10"), "unknown load preset"),
    ],
)
def test_bad_loads_are_refused(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_scaled_loads_are_the_masses_times_the_factor():
    # A mass x f hangs f times the force (F = m g), its covariance f^2 times (a std f times); a label
    # without a mass gets ' x f'; the given cases are left as they were.
    base = [load_from_mass(0.5, "+y"), LoadCase(np.array([0.0, 0.0, -3.0]), 0.01 * np.eye(3), "push")]
    base[0] = LoadCase(base[0].force, 0.04 * np.eye(3), base[0].label)
    out = scaled_loads(base, 20)
    np.testing.assert_allclose(out[0].force, load_from_mass(10.0, "+y").force, rtol=1e-15)
    np.testing.assert_allclose(out[0].cov, 0.04 * 400 * np.eye(3), rtol=1e-15)
    np.testing.assert_allclose(out[1].force, [0.0, 0.0, -60.0])
    assert [ld.label for ld in out] == ["10 kg +y", "push x 20"]
    np.testing.assert_array_equal(base[1].force, [0.0, 0.0, -3.0])
    for bad in (0.0, -2.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="factor must be a positive number"):
            scaled_loads(base, bad)
