"""Errors and warnings that stiffmap raises for user input, and its control-flow signals.

A user mistake (a bad file, a missing column, a design that cannot determine the
unknowns) raises :class:`InputError`, whose message names the file, the field or
row, and what was expected. The command-line interface prints that one line and
exits with a non-zero status; it never shows a traceback for an ``InputError``.

A wrong *value* given to a library function is a :class:`FieldError`: the field in the
function's own terms (``"params"``, ``"load_unit"``), the value and the reason, as data.
Whoever gave the value words it in its own vocabulary -- the command line names its option
(``--load-unit``), the campaign spec its key (``sensor.load_unit``) -- with
:meth:`FieldError.worded`; no caller rewrites message text.

Not every exception is a mistake: :class:`Stop` ends work early on purpose (a capture the
operator stopped, a camera source that came to its end), and :class:`FitError` says a
numerical fit could not be done or did not converge. Neither is an ``InputError``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

__all__ = [
    "InputError",
    "FieldError",
    "DesignError",
    "Stop",
    "FitError",
    "StiffmapWarning",
    "IllConditionedWarning",
]


class InputError(ValueError):
    """Bad user input: the message says where (file, row, key) and what was expected.

    ``items`` says, as data, which items of a collection the error is about
    (``{"position": 3, "load": 2}``, 1-based): a caller that knows where the items came from
    (a positions file) can name it without reading the message.
    """

    def __init__(
        self, message: str, *, source: str | None = None, items: Mapping[str, int] | None = None
    ) -> None:
        self.source = source
        self.detail = message
        self.items = dict(items or {})
        super().__init__(f"{source}: {message}" if source else message)

    def with_source(self, source: str) -> InputError:
        """Return the same error attributed to ``source`` (a file name), keeping its class."""
        if self.source:
            return self
        err = type(self).__new__(type(self))
        err.__dict__.update(self.__dict__)
        InputError.__init__(err, self.detail, source=source, items=self.items)
        return err


class FieldError(InputError):
    """A wrong value, as data: which field, what value, why; the caller words the field.

    Parameters
    ----------
    fields : str or sequence of str
        The field(s) in the raising function's terms (a parameter or attribute name such as
        ``"load_unit"``, or a dotted path such as ``"params.kj"``); the first is the field
        that is wrong, others are fields the reason mentions.
    reason : str
        Why, as a sentence that may name the fields as ``{load_unit}`` (replaced by their
        names when the error is worded); without placeholders it follows ``FIELD: ``.
    value : object, optional
        The value given.
    items : mapping of str to int, optional
        As :class:`InputError`.
    source : str, optional
        The file, as :class:`InputError`.

    Examples
    --------
    >>> e = FieldError("load_unit", "the load channel is in volts; set {load_unit} = V")
    >>> str(e)
    'the load channel is in volts; set load_unit = V'
    >>> str(e.worded({"load_unit": "--load-unit"}))
    'the load channel is in volts; set --load-unit = V'
    >>> str(FieldError("params", "unknown parameter kk").worded({"params": "--param"}))
    '--param: unknown parameter kk'
    """

    _NO_VALUE = object()

    def __init__(
        self,
        fields: str | Sequence[str],
        reason: str,
        *,
        value: object = _NO_VALUE,
        items: Mapping[str, int] | None = None,
        source: str | None = None,
    ) -> None:
        self.fields = (fields,) if isinstance(fields, str) else tuple(fields)
        self.reason = reason
        self.value = value
        super().__init__(self._text({}), source=source, items=items)

    @property
    def field(self) -> str:
        """The field that is wrong."""
        return self.fields[0]

    @property
    def has_value(self) -> bool:
        return self.value is not FieldError._NO_VALUE

    def _text(self, names: Mapping[str, str]) -> str:
        def name(f: str) -> str:
            head, dot, rest = f.partition(".")
            return names.get(f) or (names[head] + dot + rest if head in names else f)

        text, placed = self.reason, False
        for f in self.fields:  # only the fields' own placeholders: a file name may hold braces
            token = "{" + f + "}"
            if token in text:
                text, placed = text.replace(token, name(f)), True
        return text if placed else f"{name(self.field)}: {text}"

    def worded(self, names: Mapping[str, str]) -> InputError:
        """The same problem in a caller's vocabulary: each field named as ``names`` says.

        ``names`` maps a field (or the head of a dotted field) to its name for the user, an
        option (``"--param"``) or a key (``"robot.params"``); fields it lacks keep their own
        name. The result is a :class:`FieldError` of the same fields, whose text uses those
        names.
        """
        err = FieldError(self.fields, self.reason, items=self.items, source=self.source)
        err.value = self.value
        InputError.__init__(err, self._text(names), source=self.source, items=self.items)
        return err


class Stop(Exception):  # noqa: N818 - a signal, not an error
    """Work stopped early on purpose, not a mistake: a capture the operator ended, a source with
    no more frames. The message says why; a command reports it and exits as its docs say."""

    def __init__(self, message: str, *, source: str | None = None) -> None:
        self.source = source
        self.detail = message
        super().__init__(f"{source}: {message}" if source else message)


class FitError(Exception):
    """A numerical fit could not be done or did not converge (the data may be fine: another
    method or starting point may work). Not an :class:`InputError`."""


class DesignError(InputError):
    """The experiment cannot determine the unknowns (too few independent loads, ...)."""


class StiffmapWarning(UserWarning):
    """Base class of stiffmap's warnings."""


class IllConditionedWarning(StiffmapWarning):
    """A least-squares design is badly conditioned: results are sensitive to noise."""
