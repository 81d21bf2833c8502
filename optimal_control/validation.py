"""Checks on config values a user types, run when a config is built (before any work).

Oracle configs call :func:`require_finite_fields` from ``__post_init__``: a NaN or infinite float
(``--vx nan``, ``--duration inf``) is named with its field and flag instead of surfacing later as
a NaN wrench or an endless loop. Sizes (a duration, a knot count, a step that sets how many
samples there are) are bounded with :func:`require_within`: ``--duration 1e9`` is refused with the
limit and its reason, not answered by an overflow inside placo or an hour of work.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any


def flag_name(field: str) -> str:
    """The command-line flag of a config field (``max_force_n`` -> ``--max-force-n``)."""
    return "--" + field.replace("_", "-")


def require_finite_fields(cfg: Any) -> None:
    """Raise :class:`ValueError` if a float field (or an entry of a tuple field) of dataclass
    ``cfg`` is NaN or infinite; the message names the config, the field, its flag and the value."""
    for field in dataclasses.fields(cfg):
        value = getattr(cfg, field.name)
        values = value if isinstance(value, tuple | list) else (value,)
        for item in values:
            if isinstance(item, float) and not math.isfinite(item):
                raise ValueError(
                    f"{type(cfg).__name__}.{field.name} ({flag_name(field.name)}) is {value}; "
                    "give a finite number."
                )


def require_within(
    cfg: Any, name: str, low: float, high: float, unit: str, why: str, low_open: bool = False
) -> None:
    """Raise :class:`ValueError` unless field ``name`` of ``cfg`` lies in ``[low, high]`` (``(low,
    high]`` with ``low_open``). For sizes (a duration, a count of knots, a step that sets how many
    samples there are): the message names the config, the field, its flag, the limit and ``why``
    the limit is there, before any work (and not as an overflow deep inside a solver)."""
    value = getattr(cfg, name)
    if (low < value <= high) if low_open else (low <= value <= high):
        return
    bracket = "(" if low_open else "["
    raise ValueError(
        f"{type(cfg).__name__}.{name} ({flag_name(name)}) is {value:g} {unit}; give a value in "
        f"{bracket}{low:g}, {high:g}] {unit}: {why}."
    )


PHYSICAL = "outside anything a G1 motion or its solve could use"
"""Why a plain physical bound is there (:func:`require_ranges`)."""


def require_ranges(
    cfg: Any, ranges: dict[str, tuple[float, float, str]], why: str = PHYSICAL, prefix: str = ""
) -> None:
    """:func:`require_within` for each field of ``ranges`` (name -> low, high, unit); a tuple
    field has each entry checked; ``prefix``: the flags' (``clip_`` for ``--clip-*``). Every
    number of a config gets a range where it is declared: ``--alphas 1e30`` is refused by name,
    not carried into a solve."""
    for name, (low, high, unit) in ranges.items():
        value = getattr(cfg, name)
        for item in value if isinstance(value, tuple | list) else (value,):
            if not low <= item <= high:
                bracket = f"[{low:g}, {high:g}] {unit}".rstrip()
                raise ValueError(
                    f"{type(cfg).__name__}.{name} ({flag_name(prefix + name)}) is "
                    f"{f'{item:g} {unit}'.rstrip()}; give a value in {bracket}: {why}."
                )
