"""Errors and warnings that stiffmap raises for user input.

A user mistake (a bad file, a missing column, a design that cannot determine the
unknowns) raises :class:`InputError`, whose message names the file, the field or
row, and what was expected. The command-line interface prints that one line and
exits with a non-zero status; it never shows a traceback for an ``InputError``.
"""

from __future__ import annotations

__all__ = ["InputError", "DesignError", "StiffmapWarning", "IllConditionedWarning"]


class InputError(ValueError):
    """Bad user input: the message says where (file, row, key) and what was expected."""

    def __init__(self, message: str, *, source: str | None = None) -> None:
        self.source = source
        self.detail = message
        super().__init__(f"{source}: {message}" if source else message)

    def with_source(self, source: str) -> InputError:
        """Return the same error attributed to ``source`` (a file name), keeping its class."""
        if self.source:
            return self
        err = type(self).__new__(type(self))
        InputError.__init__(err, self.detail, source=source)
        return err


class DesignError(InputError):
    """The experiment cannot determine the unknowns (too few independent loads, ...)."""


class StiffmapWarning(UserWarning):
    """Base class of stiffmap's warnings."""


class IllConditionedWarning(StiffmapWarning):
    """A least-squares design is badly conditioned: results are sensitive to noise."""
