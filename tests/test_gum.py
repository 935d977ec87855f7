"""GUM presentation: U to two significant digits, the value to the same decimal place."""

from __future__ import annotations

import math
from decimal import Decimal

from hypothesis import given
from hypothesis import strategies as st

from hil.gum import format_result, rounded_pair

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=1e-9, max_value=1e5, allow_nan=False, allow_infinity=False)


def _decimals(text: str) -> int:
    return len(text.split(".")[1]) if "." in text else 0


def _significant_digits(text: str) -> str:
    return text.replace(".", "").lstrip("0")


@given(value=finite, u=positive)
def test_uncertainty_has_two_significant_digits_and_the_value_its_decimal_place(
    value: float, u: float
) -> None:
    value_text, u_text = rounded_pair(value, u)
    assert "e" not in value_text.lower() + u_text.lower()
    assert _decimals(value_text) == _decimals(u_text)
    digits = _significant_digits(u_text)
    assert len(digits) == 2 or (len(digits) > 2 and set(digits[2:]) == {"0"})  # 1200
    last_place = Decimal(1).scaleb(-_decimals(u_text)) if "." in u_text else None
    step = float(last_place) if last_place is not None else 10.0 ** (len(u_text) - 2)
    assert abs(float(u_text) - u) <= step / 2 * (1 + 1e-9)
    assert abs(float(value_text) - value) <= step / 2 * (1 + 1e-9) + 4 * math.ulp(value)


def test_worked_examples() -> None:
    assert rounded_pair(0.00038837, 0.00013) == ("0.00039", "0.00013")
    assert rounded_pair(2.59276, 0.044) == ("2.593", "0.044")
    assert rounded_pair(0.998318, 0.04) == ("0.998", "0.040")
    assert rounded_pair(1.0, 0.0996) == ("1.00", "0.10")  # rounding up to a new decade
    assert rounded_pair(35612.3, 1234) == ("35600", "1200")
    assert format_result(0.100999, 0.0012, "N·m/A") == "0.1010 ± 0.0012 N·m/A"


def test_without_an_uncertainty_the_value_keeps_six_digits() -> None:
    assert rounded_pair(0.123456789, 0.0) == ("0.123457", "0")
    assert rounded_pair(math.nan, 0.1)[0] == "nan"
