"""Checks of setting values (type and range), each naming the setting.

Every function returns the value in its canonical Python type or raises
:class:`ValueError` with ``"<name> must be ..., got <value!r>"``, where ``name`` is the
setting's dotted name (e.g. ``slam.sub_size``). Booleans are not numbers here, and floats
are not integers (``2.0`` is refused where an integer is expected), as in the JSON schema
of the workflow's config.
"""

import math
import numbers
from collections.abc import Sequence


def integer(name: str, value, minimum: int) -> int:
    """``value`` as an int >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def number(
    name: str,
    value,
    minimum: float = -math.inf,
    maximum: float = math.inf,
    open_minimum: bool = False,
    open_maximum: bool = False,
) -> float:
    """``value`` as a finite float in the range given (closed ends unless ``open_*``)."""
    valid = (
        not isinstance(value, bool)
        and isinstance(value, numbers.Real)
        and math.isfinite(value)
        and (value > minimum if open_minimum else value >= minimum)
        and (value < maximum if open_maximum else value <= maximum)
    )
    if not valid:
        raise ValueError(
            f"{name} must be a number{_range(minimum, maximum, open_minimum, open_maximum)}, "
            f"got {value!r}"
        )
    return float(value)


def boolean(name: str, value) -> bool:
    """``value`` if it is True or False."""
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def choice(name: str, value, choices: Sequence):
    """``value`` if it is one of ``choices`` (compared with its type: ``"4"`` is not 4)."""
    if not any(type(value) is type(c) and value == c for c in choices):
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value


def pair(name: str, value, check, what: str) -> tuple:
    """A list or tuple of two elements, each passed through ``check(name, element)``;
    ``what`` describes the pair in the message (e.g. "two numbers (x, y) in arcsec")."""
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"{name} must be {what}, got {value!r}")
    try:
        return tuple(check(name, element) for element in value)
    except ValueError:
        raise ValueError(f"{name} must be {what}, got {value!r}") from None


def _range(minimum: float, maximum: float, open_minimum: bool, open_maximum: bool) -> str:
    if math.isinf(maximum):
        return "" if math.isinf(minimum) else f" {'>' if open_minimum else '>='} {minimum:g}"
    if math.isinf(minimum):
        return f" {'<' if open_maximum else '<='} {maximum:g}"
    left, right = "(" if open_minimum else "[", ")" if open_maximum else "]"
    return f" in {left}{minimum:g}, {maximum:g}{right}"
