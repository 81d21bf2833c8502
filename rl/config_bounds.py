"""Bounds of the numeric config fields, checked in each config's ``__post_init__`` where the
field is declared (a saved config is checked on load too)."""

from __future__ import annotations

MAX_SEED = 2**31 - 1
"""Largest seed a config accepts: numpy's legacy seeding takes ``[0, 2**32)``, and a distributed
run adds the rank to the seed [-]."""


def _number(value: float) -> str:
    """``value`` as a range end: integers in full, floats short."""
    return str(value) if isinstance(value, int) else f"{value:g}"


def check_range(
    value: float,
    flag: str,
    low: float,
    high: float = float("inf"),
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> None:
    """Refuse ``value`` (of ``flag``) outside ``[low, high]`` (``(low`` when ``low_open``,
    ``high)`` when ``high_open``), NaN included, in one line naming the flag and the range."""
    above = low < value if low_open else low <= value
    below = value < high if high_open else value <= high
    if not (above and below):
        if high == float("inf"):
            span = f"{'>' if low_open else '>='} {_number(low)}"
        else:
            span = (
                f"in {'(' if low_open else '['}{_number(low)}, {_number(high)}"
                f"{')' if high_open else ']'}"
            )
        raise ValueError(f"{flag} must be {span}, got {value}")


def check_pair(
    value: object, flag: str, low: float, high: float, *, low_open: bool = False
) -> None:
    """Refuse a range ``value`` (of ``flag``) that is not two numbers ``LOW HIGH`` with
    ``LOW <= HIGH``, both in ``[low, high]`` (``(low`` when ``low_open``), NaN included, in one
    line naming the flag, the form and the bounds."""
    pair = isinstance(value, tuple | list) and len(value) == 2
    numbers = pair and all(
        isinstance(v, int | float) and not isinstance(v, bool)
        for v in value  # type: ignore[union-attr]
    )
    if numbers:
        first, second = value  # type: ignore[misc]
        inside = [(low < v if low_open else low <= v) and v <= high for v in (first, second)]
        if all(inside) and first <= second:
            return
    if isinstance(value, tuple | list):
        shown = " ".join(
            _number(v) if isinstance(v, int | float) and not isinstance(v, bool) else repr(v)
            for v in value
        )
    else:
        shown = repr(value)
    span = f"{'(' if low_open else '['}{_number(low)}, {_number(high)}]"
    raise ValueError(
        f"{flag} must be two numbers LOW HIGH in {span} with LOW <= HIGH, got {shown or 'none'}"
    )
