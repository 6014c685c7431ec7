"""The examples in the docstrings of the functions a user calls first run and give what they show.

Each module's doctests run with :func:`doctest.testmod` (warnings are errors, as in every
test). A module is listed here, not found by ``--doctest-modules``: that option would also
collect stiffmap's functions named ``test...`` (``testbed``) as tests, and import every module.
The entry points named below must keep an example, so that a docstring losing its example
fails here rather than silently running nothing.
"""

from __future__ import annotations

import doctest
import importlib

import pytest

#: Module -> the public functions and classes whose docstrings must hold an example.
EXAMPLES = {
    "stiffmap.identify": ["identify_stiffness"],
    "stiffmap.targets": ["Chessboard"],
    "stiffmap.geometry": ["transform_points", "concat", "matrix_from_euler", "stiffness_in_frame"],
    "stiffmap.kinds.registry": ["robot_from_options", "params_from_text"],
    "stiffmap.models.base": ["LegMechanism.evaluate"],
    "stiffmap.models.presets": [],
    "stiffmap.models.mobility": ["platform_mobility", "reachable_poses"],
    "stiffmap.loads": ["scaled_loads"],
    "stiffmap.sensors.analysis": ["analyse_recording"],
    "stiffmap.sensors.plateaus": ["detect_plateaus"],
    "stiffmap.campaign.simulate": [],
    "stiffmap.errors": [],
    "stiffmap.rig": [],
    "stiffmap.stats": ["excess_dispersion"],
}


def _docstring(module, dotted: str) -> str:
    obj = module
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj.__doc__ or ""


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_docstring_examples_run(name, capsys):
    module = importlib.import_module(name)
    for entry in EXAMPLES[name]:
        assert ">>>" in _docstring(module, entry), f"{name}.{entry} lost its example"
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report = capsys.readouterr().out
    assert result.attempted > 0, f"{name} holds no example"
    assert result.failed == 0, report
