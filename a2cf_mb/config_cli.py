"""Typed dataclass configs as command-line flags, so no default is written twice.

Each field of a (flat) config dataclass becomes ``--field-name`` with the field's type, its default
and its trailing ``# comment`` as help, then :func:`config_from_args` rebuilds the dataclass.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import typing
from typing import Any, TypeVar

T = TypeVar("T")


def _field_comments(cls: type) -> dict[str, str]:
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    comments: dict[str, str] = {}
    for match in re.finditer(r"^\s+(\w+)\s*:[^#\n]*#\s*(.+)$", source, re.MULTILINE):
        comments[match.group(1)] = match.group(2).strip()
    return comments


def _flag(name: str, prefix: str) -> str:
    return "--" + (prefix + name).replace("_", "-")


def add_config_arguments(
    parser: argparse.ArgumentParser, cls: type, prefix: str = "", skip: tuple[str, ...] = ()
) -> None:
    """Add one flag per field of dataclass ``cls`` (bool fields get ``--x/--no-x``)."""
    hints = typing.get_type_hints(cls)
    comments = _field_comments(cls)
    for field in dataclasses.fields(cls):
        if field.name in skip or not field.init:
            continue
        kind = hints[field.name]
        default = (
            field.default
            if field.default is not dataclasses.MISSING
            else field.default_factory()  # type: ignore[misc]
            if field.default_factory is not dataclasses.MISSING
            else None
        )
        # argparse %-formats help strings: escape a literal percent sign.
        help_text = f"{comments.get(field.name, '')} (default: {default})".replace("%", "%%")
        dest = prefix + field.name
        if kind is bool:
            parser.add_argument(
                _flag(field.name, prefix),
                dest=dest,
                action=argparse.BooleanOptionalAction,
                default=default,
                help=help_text,
            )
            continue
        origin = typing.get_origin(kind)
        if origin in (tuple, list):
            args = typing.get_args(kind)
            parser.add_argument(
                _flag(field.name, prefix),
                dest=dest,
                type=args[0],
                nargs="+",
                default=default,
                help=help_text,
            )
            continue
        if origin is typing.Union or str(origin) == "types.UnionType":
            args = [a for a in typing.get_args(kind) if a is not type(None)]
            kind = args[0]
        parser.add_argument(
            _flag(field.name, prefix), dest=dest, type=kind, default=default, help=help_text
        )


def config_from_args(cls: type[T], args: argparse.Namespace, prefix: str = "", **extra: Any) -> T:
    """Build ``cls`` from parsed flags added by :func:`add_config_arguments` (plus ``extra``)."""
    values: dict[str, Any] = {}
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        key = prefix + field.name
        if field.init and hasattr(args, key):
            value = getattr(args, key)
            if typing.get_origin(hints[field.name]) is tuple and isinstance(value, list):
                value = tuple(value)
            values[field.name] = value
    values.update(extra)
    return cls(**values)
