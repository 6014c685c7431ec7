"""Machining with a compliant robot: compensate a program for the deflection, choose where and how to cut.

- :mod:`~stiffmap.machining.gcode`: RS274/NGC programs read and written back (every line
  that is not a move verbatim, in place);
- :mod:`~stiffmap.machining.path`, :mod:`~stiffmap.machining.forces`: the toolpath's
  geometry and the cutting force along it;
- :mod:`~stiffmap.machining.field`: a model's deflection at commanded positions;
- :mod:`~stiffmap.machining.compensate`: the commanded path whose deflected path is the
  programmed one, within a tolerance;
- :mod:`~stiffmap.machining.place`, :mod:`~stiffmap.machining.spin`: the placement of the
  program and a six-axis arm's tool spin that deflect least;
- :mod:`~stiffmap.machining.io`, :mod:`~stiffmap.machining.run`: files, and
  ``stiffmap compensate`` as one function (:func:`compensate_file`).

See ``docs/machining.md``.
"""

from .compensate import Compensation, CompensationError, compensate_path
from .forces import ForceSpec
from .run import CompensateOptions, CompensationResult, ModelUncertainty, compensate_file

__all__ = [
    "Compensation",
    "CompensationError",
    "compensate_path",
    "ForceSpec",
    "CompensateOptions",
    "CompensationResult",
    "ModelUncertainty",
    "compensate_file",
]
