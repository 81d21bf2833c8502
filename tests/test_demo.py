"""`a2cf-mb demo` end to end at a tiny budget (opt-in: about a minute on 2 cores)."""

from __future__ import annotations

import pytest

from a2cf_mb.cli import main


@pytest.mark.slow
def test_demo_runs_end_to_end(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = ["demo", "--iterations", "1", "--num-envs", "4", "--eval-envs", "2",
            "--walk-duration-s", "2.5", "--no-video", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    report = (out / "report.md").read_text()
    for needle in ("## 1. The oracle", "## 3. Evaluation, assistance off", "sim2sim",
                   "smoke-scale budget", "| baseline |", "| a2cf_warmstart |"):  # fmt: skip
        assert needle in report, needle
    assert (out / "learning_curves.png").stat().st_size > 0
    assert (out / "runs" / "a2cf_warmstart" / "warmstart.json").is_file()
    assert main(argv) == 2  # an existing output is not overwritten without --overwrite
    assert "--overwrite" in capsys.readouterr().err
