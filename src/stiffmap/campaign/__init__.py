"""Orchestration and I/O: campaign specs, the results store, runners, and file-level entry points.

The numerical cores (``geometry``, ``identify``, ``vision``, ``models``, ...)
never read files; the functions here do, and turn every file problem into an
:class:`~stiffmap.errors.InputError` that names the file and the field.
"""
