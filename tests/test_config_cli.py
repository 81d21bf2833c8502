"""Config dataclasses as flags: help that cannot get lost, given-flag tracking, finite floats."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

import pytest

from a2cf_mb.cli import build_parser
from a2cf_mb.config_cli import add_config_arguments, config_from_args, given_flags


@dataclass(frozen=True)
class Inner:
    """A nested config."""

    gain: float = 2.0  # a gain that the formatter
    # wrapped onto two lines [-]


@dataclass(frozen=True)
class Base:
    """A base config."""

    speed_mps: float = (
        1.0  # wrapped by the formatter: the comment sits inside the parentheses [m/s]
    )
    label: str = "x"
    """An attribute docstring instead of a comment."""
    # a comment block above the field,
    # two lines long [s]
    delay_s: float = 0.1


@dataclass(frozen=True)
class Child(Base):
    """Inherits speed_mps and label."""

    inner: Inner = field(default_factory=Inner)  # nested settings
    count: int = field(default=3, metadata={"help": "from the field metadata"})


def parse(argv: list[str]) -> tuple[argparse.ArgumentParser, argparse.Namespace]:
    parser = argparse.ArgumentParser()
    add_config_arguments(parser, Child)
    return parser, parser.parse_args(argv)


def test_help_survives_wrapping_inheritance_docstrings_and_metadata() -> None:
    parser, _ = parse([])
    text = " ".join(parser.format_help().split())
    assert "wrapped by the formatter: the comment sits inside the parentheses [m/s]" in text
    assert "An attribute docstring instead of a comment." in text
    assert "from the field metadata" in text
    assert "a comment block above the field, two lines long [s]" in text
    assert "--inner-gain" in text and "a gain that the formatter" in text


def test_nested_flags_given_flags_and_finite_floats(capsys) -> None:
    parser, args = parse(["--inner-gain", "3", "--count", "5"])
    cfg = config_from_args(Child, args)
    assert cfg.inner.gain == 3.0 and cfg.count == 5 and cfg.speed_mps == 1.0
    assert given_flags(args) == {"count": 5, "inner.gain": 3.0}
    for bad in ("nan", "inf", "-inf"):
        with pytest.raises(SystemExit):
            parser.parse_args(["--speed-mps", bad])
        assert "--speed-mps" in capsys.readouterr().err


def _options(parser: argparse.ArgumentParser, path: str = ""):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, f"{path} {name}")
        elif action.option_strings and action.dest != "help":
            yield path.strip(), action


def test_every_flag_of_every_command_has_help() -> None:
    """The whole CLI, including train's --env-* and --task-* flags: no flag without text."""
    missing = []
    seen = set()
    for command, action in _options(build_parser()):
        seen.add((command, action.option_strings[0]))
        text = (action.help or "").split("(default:")[0].strip()
        if not text:
            missing.append(f"{command} {action.option_strings[0]}")
    assert not missing, missing
    help_of = {(c, a.option_strings[0]): a.help for c, a in _options(build_parser())}
    assert "percentile" in help_of[("solve-backflip", "--oracle-percentile")]  # inherited field
    for flag in ("--env-num-threads", "--env-num-envs", "--task-pushes-velocity-xy-mps",
                 "--task-episode-length-s", "--task-scene-link-collisions", "--ppo-learning-rate",
                 "--task-reward-weight", "--task-term-param"):  # fmt: skip
        assert ("train", flag) in seen, flag


def test_train_takes_the_short_flags_other_rl_tools_use() -> None:
    """``--num-envs`` and ``--seed`` (Isaac Lab / mjlab spelling) are second spellings of
    ``--env-num-envs`` and ``--env-seed``: the same dest, no second field; ``--device`` is
    TrainConfig's own; ``--help`` lists both spellings."""
    from rl.training.config import TrainConfig

    parser = build_parser("train")
    short = parser.parse_args(["train", "--num-envs", "4096", "--seed", "7", "--device", "cuda:0"])
    long = parser.parse_args(["train", "--env-num-envs", "4096", "--env-seed", "7"])
    cfg = config_from_args(TrainConfig, short)
    assert (cfg.env.num_envs, cfg.seed, cfg.device) == (4096, 7, "cuda:0")
    assert cfg.env == config_from_args(TrainConfig, long).env
    assert given_flags(short) == {"device": "cuda:0", "env.num_envs": 4096, "env.seed": 7}
    assert not hasattr(short, "num_envs") and not hasattr(short, "seed")
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    text = " ".join(sub.choices["train"].format_help().split())
    assert "--env-num-envs NUM_ENVS, --num-envs NUM_ENVS" in text
    assert "--env-seed SEED, --seed SEED" in text and "--device DEVICE" in text


def test_cli_reference_in_docs_is_current() -> None:
    """docs/cli.md is the parser's own help; regenerate it with the command in its header."""
    from pathlib import Path

    from a2cf_mb.cli_reference import render

    path = Path(__file__).resolve().parents[1] / "docs" / "cli.md"
    assert path.read_text() == render(), (
        "docs/cli.md is stale: python -m a2cf_mb.cli_reference > docs/cli.md"
    )
