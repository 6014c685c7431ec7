"""Orchestration and I/O: campaign specs, the results store, runners, and file-level entry points.

The numerical cores (``geometry``, ``identify``, ``vision``, ``models``, ...)
never read files; the functions here do, and turn every file problem into an
:class:`~stiffmap.errors.InputError` that names the file and the field. The
campaign format is known here only: the spec (``spec``, ``spec_writer``), the
results database (``store``, the one home of its SQL), the runs (``runner``
with ``positions``, ``measure``, ``derive``; ``sensor_runner``), the exports,
and the simulated campaigns the virtual test-bed's data becomes
(``simulated``, ``simulated_sensor``, ``truth``).
"""
