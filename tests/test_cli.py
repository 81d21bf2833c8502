"""The CLI skeleton: help, info and the physics benchmark run end to end."""

from __future__ import annotations

import json

import pytest

from a2cf_mb.bench.sim import SimBenchConfig, format_results, run_sim_benchmark
from a2cf_mb.cli import UsageError, build_parser, main


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("info", "bench"):
        assert command in out


def test_info_prints_the_joint_table(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "33.341 kg" in out
    assert "right_wrist_yaw_joint" in out
    assert out.count("_joint") == 29


def test_bench_flags_come_from_the_config():
    args = build_parser().parse_args(["bench", "sim", "--num-rollouts", "3"])
    assert args.num_rollouts == 3
    assert args.num_steps == SimBenchConfig().num_steps


def test_bench_sim_reports_rates_and_ratios(tmp_path, capsys):
    out_file = tmp_path / "sim.json"
    assert (
        main(
            [
                "bench",
                "sim",
                "--num-rollouts",
                "4",
                "--num-steps",
                "40",
                "--repeats",
                "1",
                "--output",
                str(out_file),
            ]
        )
        == 0
    )
    results = json.loads(out_file.read_text())
    assert results["ratios_to_single_stand"]["single_stand"] == pytest.approx(1.0)
    for key in ("single_random", "rollout_stand", "rollout_random"):
        assert results[key + "_steps_per_s"] > 0
    assert "steps/s" in capsys.readouterr().out
    assert "single_stand" in format_results(run_sim_benchmark(SimBenchConfig(4, 8, 1, 1)))


def test_input_errors_print_one_clear_line(capsys, monkeypatch):
    monkeypatch.delenv("A2CF_DEBUG", raising=False)
    assert main(["train", "--mode", "bogus", "--iterations", "1"]) == 2
    err = capsys.readouterr().err
    assert "unknown training mode 'bogus'" in err
    assert "Traceback" not in err


def test_percent_in_a_config_comment_does_not_break_help():
    import argparse
    from dataclasses import dataclass

    from a2cf_mb.config_cli import add_config_arguments

    @dataclass
    class Cfg:
        margin: float = 1.5  # 95% percentile margin [-]

    parser = argparse.ArgumentParser()
    add_config_arguments(parser, Cfg)
    assert "95%" in parser.format_help()


def test_a_named_command_does_not_import_the_others_libraries() -> None:
    """``a2cf-mb solve-backflip ...`` builds only its own parser: torch and rsl-rl (the RL
    commands') stay unimported; an unknown command still lists every command."""
    import subprocess
    import sys

    code = ("import sys; from a2cf_mb.cli import build_parser; build_parser('solve-backflip'); "
            "print(sorted({'torch', 'rsl_rl'} & set(sys.modules)))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    with pytest.raises(UsageError, match="invalid choice.*solve-backflip"):
        build_parser("nosuch").parse_args(["nosuch"])
