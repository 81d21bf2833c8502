"""``a2cf-mb eval-curve RUN_DIR``: the motion policy alone at every kept checkpoint of a run."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``eval-curve`` subcommand."""
    from rl.evaluation.config import AloneEvalConfig

    parser = subparsers.add_parser(
        "eval-curve",
        help="evaluate the motion policy alone (assistance off) at every kept checkpoint of a run "
        "(evals_checkpoints.jsonl)",
    )
    parser.add_argument("run_dir", help="run folder written by `a2cf-mb train`")
    add_config_arguments(parser, AloneEvalConfig)
    parser.add_argument(
        "--every-iterations",
        type=int,
        default=1,
        help="only checkpoints whose iteration is a multiple of this (default: 1, all)",
    )
    parser.add_argument(
        "--iterations",
        type=int,
        nargs="+",
        default=(),
        metavar="K",
        help="evaluate only these kept checkpoints model_K.pt (default: all)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Call :func:`rl.evaluation.policy.evaluate_checkpoints` and print where the target was reached."""
    from rl.config_bounds import check_range
    from rl.evaluation.alone import first_reached_once, target_held
    from rl.evaluation.config import AloneEvalConfig
    from rl.evaluation.policy import evaluate_checkpoints
    from rl.runs.folder import CHECKPOINT_EVALS_LOG

    check_range(args.every_iterations, "--every-iterations", 1, 1_000_000_000)
    rows = evaluate_checkpoints(
        args.run_dir,
        # the config's checks name train's --eval-* flags; these are eval-curve's own
        config_from_args(AloneEvalConfig, args, flags_declared_as="eval."),
        every_iterations=args.every_iterations,
        iterations=tuple(args.iterations),
    )
    if not rows:
        print(f"no checkpoint of {args.run_dir} evaluated with these envs and seed")
        return 0
    held = target_held(rows)
    once = first_reached_once(rows)
    if held:
        where = (
            f"held at two consecutive checkpoints from iteration {held['iteration']} "
            f"({held['env_steps']:,} env steps)"
        )
    elif once:
        where = (
            f"reached at iteration {once['iteration']}, never at two consecutive checkpoints "
            "(one evaluation is one noisy draw)"
        )
    else:
        where = "not reached"
    print(
        f"{len(rows)} checkpoints in {args.run_dir}/{CHECKPOINT_EVALS_LOG}; target {rows[-1]['target']}: {where}"
    )
    return 0
