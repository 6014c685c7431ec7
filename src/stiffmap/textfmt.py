"""Numbers as text: the one formatter of the command line and the report.

The command line prints 5 significant digits by default, the report's tables
and hover texts 4; each caller passes its own count, so both keep what they
print. A standard error is always shown with 2 digits.
"""

from __future__ import annotations

import math

__all__ = ["fmt", "fmt_pm"]


def fmt(x: float, digits: int = 5) -> str:
    """``x`` with ``digits`` significant digits (``%g``); ``n/a`` when not finite.

    Something that is not a number (a string, None) is returned as ``str(x)``.
    """
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(xf):
        return "n/a"
    return f"{xf:.{digits}g}"


def fmt_pm(x: float, s: float, digits: int = 5, *, omit_unknown_std: bool = False) -> str:
    """``x ± s``: ``x`` with ``digits`` significant digits, ``s`` with 2.

    With ``omit_unknown_std`` a standard error that is not finite (a fixed
    parameter, a missing uncertainty) is left out: ``x`` alone; otherwise it
    prints as ``n/a``.
    """
    if omit_unknown_std and not math.isfinite(float(s)):
        return fmt(x, digits)
    return f"{fmt(x, digits)} ± {fmt(s, 2)}"
