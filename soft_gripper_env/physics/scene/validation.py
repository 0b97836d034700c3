"""Validation of configuration values, shared by every frozen dataclass of the core."""

from __future__ import annotations

import math


def check_range(owner: str, name: str, value: float, unit: str, low: float, high: float = math.inf,
                low_inclusive: bool = False, high_inclusive: bool = False) -> None:
    """Raise ``ValueError`` unless ``low < value < high`` (``low <= value`` when ``low_inclusive``, ``value <= high``
    when ``high_inclusive``).

    The message names ``owner.name``, the value, its unit and the allowed range, so a user can fix the call.
    """
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name} = {value!r} is not a number [{unit}]") from None
    above_low = value >= low if low_inclusive else value > low
    below_high = value <= high if high_inclusive else value < high
    if not (math.isfinite(value) and above_low and below_high):
        left, right = "[" if low_inclusive else "(", "]" if high_inclusive else ")"
        raise ValueError(f"{owner}.{name} = {value!r} {unit} is outside the allowed range "
                         f"{left}{low:g}, {high:g}{right} {unit}")
