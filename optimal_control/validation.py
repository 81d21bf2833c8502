"""Checks on config values a user types, run when a config is built (before any work).

Oracle configs call :func:`require_finite_fields` from ``__post_init__``: a NaN or infinite float
(``--vx nan``, ``--duration inf``) is named with its field and flag instead of surfacing later as
a NaN wrench or an endless loop.
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
