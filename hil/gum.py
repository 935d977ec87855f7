"""How a person reads a result (GUM 7.2.6): the expanded uncertainty to two significant
digits, the value rounded to the same decimal place. Records (JSON) keep full precision."""

from __future__ import annotations

import math
from decimal import ROUND_HALF_EVEN, Decimal


def rounded_pair(value: float, expanded_uncertainty: float) -> tuple[str, str]:
    """``value`` and ``U`` as strings rounded for reading.

    Parameters
    ----------
    value : float
        The measured value.
    expanded_uncertainty : float
        Its expanded uncertainty ``U`` (same unit).

    Returns
    -------
    value_text, uncertainty_text : str
        ``U`` with two significant digits and ``value`` to the same decimal place
        (``0.0038837 ± 0.00013`` → ``"0.00388"``, ``"0.00013"``). Without a positive, finite
        ``U`` the value keeps six significant digits and ``U`` is written as it is.
    """
    if not math.isfinite(value):
        return f"{value}", f"{expanded_uncertainty:.2g}"
    if not math.isfinite(expanded_uncertainty) or expanded_uncertainty <= 0:
        return f"{value:.6g}", f"{expanded_uncertainty:.2g}"
    u = Decimal(repr(expanded_uncertainty))
    place = u.adjusted() - 1  # exponent of the second significant digit
    u_rounded = u.quantize(Decimal(1).scaleb(place), rounding=ROUND_HALF_EVEN)
    if u_rounded.adjusted() > u.adjusted():  # 9.96 → 10.0: keep two digits
        place += 1
        u_rounded = u.quantize(Decimal(1).scaleb(place), rounding=ROUND_HALF_EVEN)
    quantum = Decimal(1).scaleb(place)
    v_rounded = Decimal(repr(value)).quantize(quantum, rounding=ROUND_HALF_EVEN)
    return _plain(v_rounded, place), _plain(u_rounded, place)


def format_result(value: float, expanded_uncertainty: float, unit: str = "") -> str:
    """``"value ± U unit"`` rounded as :func:`rounded_pair` says."""
    value_text, u_text = rounded_pair(value, expanded_uncertainty)
    return f"{value_text} ± {u_text}" + (f" {unit}" if unit else "")


def _plain(number: Decimal, place: int) -> str:
    """Fixed-point text with ``max(-place, 0)`` decimals (no exponent notation)."""
    decimals = max(-place, 0)
    return f"{number:.{decimals}f}"


def significant(number: float, digits: int = 2) -> str:
    """``number`` to ``digits`` significant digits, trailing zeros kept, never a trailing
    decimal point (``18`` not ``18.``; ``0.0050``; ``180``; ``2.8e-05`` below 10⁻⁴).

    Parameters
    ----------
    number : float
        Any number (a standard uncertainty, a contribution).
    digits : int
        Significant digits.

    Returns
    -------
    str
        Fixed-point text between 10⁻⁴ and 10⁶, else mantissa and exponent.
    """
    if not math.isfinite(number):
        return f"{number}"
    if number == 0:
        return "0"
    rounded = Decimal(repr(number)).quantize(
        Decimal(1).scaleb(Decimal(repr(number)).adjusted() - digits + 1),
        rounding=ROUND_HALF_EVEN)
    exponent = rounded.adjusted()  # 9.96 → 10: one more digit before the point
    if not -4 <= exponent < 6:
        return f"{float(rounded):.{digits - 1}e}"
    return _plain(rounded, exponent - digits + 1)
