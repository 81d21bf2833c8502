"""Typed dataclass configs as command-line flags, so no default is written twice.

Each field of a config dataclass becomes ``--prefix-field-name`` with the field's type and default;
nested dataclass fields recurse (``TrainConfig.ppo.learning_rate`` -> ``--ppo-learning-rate``).
Help text comes from the field itself: ``field(metadata={"help": ...})``, else the comment on the
field's own lines (however the formatter wrapped them), else a comment block right above it, else
a docstring right below the field, searched through the class and its bases, so inherited fields
keep theirs. The project's configs use the trailing comment (one line: what the field is and its
unit; why, in a comment above) and metadata only for computed text. Tests check that every flag
of every command has help and that it fits one line of ``docs/cli.md``. Float flags refuse NaN
and infinity by name. The parsed namespace records which flags were given (:func:`given_flags`),
e.g. to say what a ``--resume`` will not apply. A few nested fields also take the short flag other
RL tools use (:data:`SHORT_FLAGS`: ``--num-envs`` for ``--env-num-envs``), as a second spelling of
the same option, not a second field.

Why not tyro (which mjlab uses): it would give the same flags, but ``--resume`` needs to know which
flags the user typed, the bool ``--x/--no-x`` style and the one-line error messages are ours, and
the whole layer is ~150 lines with tests; revisit if configs grow unions or subcommand trees.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import io
import math
import re
import textwrap
import tokenize
import types
import typing
from functools import cache
from typing import Any, TypeVar

T = TypeVar("T")

GIVEN = "_given_flags"
"""Namespace attribute: the set of ``dest`` names the user gave on the command line."""

SHORT_FLAGS: dict[str, str] = {
    "env.num_envs": "--num-envs",
    "env.seed": "--seed",
    "env.backend": "--backend",
}
"""dest -> the flag Isaac Lab and mjlab users type for it, accepted beside the long flag (both set
the same dest; ``--help`` lists both). A top-level field already has the short form
(``--device``)."""


@cache
def _class_field_help(cls: type) -> dict[str, str]:
    """Field name -> help from the comments or docstrings in the source of ``cls`` itself."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    tree = ast.parse(source)
    comments: dict[int, str] = {}
    own_line: set[int] = set()  # lines holding nothing but a comment
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
            if tok.line.strip().startswith("#"):
                own_line.add(tok.start[0])
    node = tree.body[0]
    found: dict[str, str] = {}
    body = getattr(node, "body", [])
    for i, stmt in enumerate(body):
        if not isinstance(stmt, ast.AnnAssign) or not isinstance(stmt.target, ast.Name):
            continue
        lines = range(stmt.lineno, (stmt.end_lineno or stmt.lineno) + 1)
        text = " ".join(comments[line] for line in lines if line in comments)
        above = stmt.lineno - 1
        while not text and above in own_line:  # a comment block right above the field
            above -= 1
        if not text and above < stmt.lineno - 1:
            text = " ".join(comments[line] for line in range(above + 1, stmt.lineno))
        nxt = body[i + 1] if i + 1 < len(body) else None
        if (
            not text
            and isinstance(nxt, ast.Expr)
            and isinstance(nxt.value, ast.Constant)
            and isinstance(nxt.value.value, str)
        ):
            text = " ".join(nxt.value.value.split())
        if text:
            found[stmt.target.id] = text
    return found


def field_help(cls: type, field: dataclasses.Field) -> str:
    """Help text of one field of ``cls`` (metadata, own comment, docstring; through the MRO)."""
    if field.metadata.get("help"):
        return str(field.metadata["help"])
    for klass in cls.__mro__:
        if dataclasses.is_dataclass(klass):
            text = _class_field_help(klass).get(field.name)
            if text:
                return text
    return ""


def _flag(dest: str) -> str:
    return "--" + dest.replace(".", "-").replace("_", "-")


def finite_float(text: str) -> float:
    """argparse type: a finite float (NaN and infinity are refused with a clear message)."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from err
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not finite; give a finite number")
    return value


class _Record(argparse.Action):
    """Store the value and remember that the flag was given."""

    def __call__(self, parser, namespace, values, option_string=None):  # noqa: D102
        setattr(namespace, self.dest, values)
        namespace.__dict__.setdefault(GIVEN, set()).add(self.dest)


class _RecordBool(argparse.BooleanOptionalAction):
    """``--x / --no-x`` that remembers it was given."""

    def __call__(self, parser, namespace, values, option_string=None):  # noqa: D102
        super().__call__(parser, namespace, values, option_string)
        namespace.__dict__.setdefault(GIVEN, set()).add(self.dest)


def _default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return field.default_factory()  # type: ignore[misc]
    return None


def add_config_arguments(
    parser: argparse.ArgumentParser,
    cls: type,
    prefix: str = "",
    skip: tuple[str, ...] = (),
    defaults: Any = None,
) -> None:
    """Add one flag per field of dataclass ``cls``, recursing into nested dataclasses.

    ``prefix`` (e.g. ``"ppo_"`` or ``"task."``) starts every dest; nested fields extend it with
    ``"<field>."``; a dest in :data:`SHORT_FLAGS` also takes its short flag. ``defaults`` (an
    instance of ``cls``) supplies the shown defaults instead of the class's (e.g. a task's own
    values). Fields whose type argparse cannot express (callables, term lists, dicts) are skipped;
    they are changed in code or by dedicated flags.
    """
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        if field.name in skip or not field.init:
            continue
        kind = hints[field.name]
        default = getattr(defaults, field.name) if defaults is not None else _default(field)
        dest = prefix + field.name
        if dataclasses.is_dataclass(kind):
            add_config_arguments(parser, kind, prefix=dest + ".", defaults=default)
            continue
        origin = typing.get_origin(kind)
        args = typing.get_args(kind)
        if origin in (typing.Union, types.UnionType):
            plain = [a for a in args if a is not type(None)]
            if len(plain) != 1:
                continue
            kind, origin, args = plain[0], typing.get_origin(plain[0]), typing.get_args(plain[0])
        text = field_help(cls, field)
        flags = [_flag(dest), *([SHORT_FLAGS[dest]] if dest in SHORT_FLAGS else [])]
        metavar = field.name.upper()
        # argparse %-formats help strings: escape a literal percent sign.
        help_text = f"{text} (default: {default})".replace("%", "%%")
        if kind is bool:
            parser.add_argument(
                *flags, dest=dest, action=_RecordBool, default=default, help=help_text
            )
        elif origin in (tuple, list) and args and args[0] in (int, float, str):
            parser.add_argument(
                *flags, dest=dest, action=_Record, nargs="+", default=default, help=help_text, metavar=metavar,
                type=finite_float if args[0] is float else args[0],
            )  # fmt: skip
        elif kind in (int, float, str):
            parser.add_argument(
                *flags, dest=dest, action=_Record, default=default, help=help_text,
                type=finite_float if kind is float else kind, metavar=metavar,
            )  # fmt: skip


def given_flags(args: argparse.Namespace, prefix: str = "") -> dict[str, Any]:
    """The dests the user gave that start with ``prefix`` (prefix removed) and their values."""
    given = getattr(args, GIVEN, set())
    return {d[len(prefix) :]: getattr(args, d) for d in sorted(given) if d.startswith(prefix)}


def replace_path(obj: T, dotted: str, value: Any) -> T:
    """``obj`` (a dataclass) with the nested field ``dotted`` (``"ppo.learning_rate"``) replaced;
    nested configs are rebuilt, so their checks run."""
    head, _, rest = dotted.partition(".")
    current = getattr(obj, head)
    if rest:
        return dataclasses.replace(obj, **{head: replace_path(current, rest, value)})
    if isinstance(current, tuple) and isinstance(value, list):
        value = tuple(value)
    return dataclasses.replace(obj, **{head: value})


def renamed_flags(message: str, cls: type, declared_as: str, prefix: str = "") -> str:
    """``message`` with the flags of ``cls``'s fields as its checks name them (declared under
    ``declared_as``: ``"eval."`` -> ``--eval-num-envs``) turned into the flags of the command
    that added them under ``prefix`` (``--num-envs``), so an error names the flag the user
    typed."""
    for field in dataclasses.fields(cls):
        old, new = _flag(declared_as + field.name), _flag(prefix + field.name)
        message = re.sub(re.escape(old) + r"(?![\w-])", new, message)
    return message


def config_from_args(
    cls: type[T],
    args: argparse.Namespace,
    prefix: str = "",
    flags_declared_as: str | None = None,
    **extra: Any,
) -> T:
    """Build ``cls`` from parsed flags added by :func:`add_config_arguments` (plus ``extra``).

    ``flags_declared_as``: the prefix under which ``cls``'s checks name its flags when the command
    adds them under another (``eval-curve``'s ``--num-envs`` is ``train``'s ``--eval-num-envs``):
    a refused value is then named by the command's own flag (:func:`renamed_flags`)."""
    values: dict[str, Any] = {}
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        key = prefix + field.name
        if not field.init or field.name in extra:
            continue
        if dataclasses.is_dataclass(hints[field.name]):
            values[field.name] = config_from_args(hints[field.name], args, prefix=key + ".")
        elif hasattr(args, key):
            value = getattr(args, key)
            if typing.get_origin(hints[field.name]) is tuple and isinstance(value, list):
                value = tuple(value)
            values[field.name] = value
    values.update(extra)
    if flags_declared_as is None:
        return cls(**values)
    try:
        return cls(**values)
    except ValueError as err:
        raise ValueError(renamed_flags(str(err), cls, flags_declared_as, prefix)) from err
