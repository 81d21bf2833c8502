"""Algorithm 1 and the switches of the A2CF assist curriculum, rule by rule."""

from __future__ import annotations

import pytest
import torch

from optimal_control.bounds import PAPER_ETA0
from rl.a2cf.algorithm1 import Algorithm1, AssistStatistics, histogram_quantile
from rl.a2cf.config import PAPER_RULES, CurriculumConfig
from rl.a2cf.curriculum import (
    AssistCurriculum,
    identical_axis_bounds,
    update_bound,
)
from rl.envs.assist import paper_bound_rows
from rl.tasks.stand.task import STAND

ETA0 = torch.tensor([[40.0, 40.0, 10.0, 40.0, 40.0, 40.0], [40.0, 40.0, 100.0, 30.0, 30.0, 30.0]])
NORM0 = torch.linalg.vector_norm(ETA0, dim=-1)
PAPER = CurriculumConfig(**PAPER_RULES)  # Algorithm 1 as the paper states it
BOTH = torch.tensor([True, True])


class Rollout:
    """Algorithm 1 fed step by step, updated after every ``steps_per_iteration`` steps (what the
    runner does once per iteration); everything else is the :class:`Algorithm1`'s."""

    def __init__(self, curriculum: AssistCurriculum, steps_per_iteration: int) -> None:
        self.algorithm = Algorithm1(curriculum)
        self.steps_per_iteration = steps_per_iteration

    def on_step(self, assist, skill_progress, alone_progress=None):
        self.algorithm.record(assist, skill_progress, alone_progress)
        if self.algorithm.steps < self.steps_per_iteration:
            return None
        return self.algorithm.end_iteration()

    def __getattr__(self, name: str):
        return getattr(self.__dict__["algorithm"], name)


def test_update_bound_shrinks_when_force_below_band() -> None:
    eta = update_bound(ETA0, 0.49 * NORM0, BOTH, False, epsilon=0.5, delta=0.2)
    torch.testing.assert_close(eta, 0.8 * ETA0)


def test_update_bound_grows_when_force_above_band() -> None:
    eta = update_bound(ETA0, 1.51 * NORM0, BOTH, False, epsilon=0.5, delta=0.2)
    torch.testing.assert_close(eta, 1.2 * ETA0)


def test_update_bound_keeps_inside_band() -> None:
    for ratio in (0.51, 1.0, 1.49):
        eta = update_bound(ETA0, ratio * NORM0, BOTH, False, epsilon=0.5, delta=0.2)
        torch.testing.assert_close(eta, ETA0)


def test_update_bound_extra_decay_when_skill_learned() -> None:
    # inside the band: only the extra decay; below the band: both decays
    inside = update_bound(ETA0, NORM0, BOTH, True, epsilon=0.5, delta=0.2)
    torch.testing.assert_close(inside, 0.8 * ETA0)
    below = update_bound(ETA0, 0.1 * NORM0, BOTH, True, epsilon=0.5, delta=0.2)
    torch.testing.assert_close(below, 0.8 * 0.8 * ETA0)
    above = update_bound(ETA0, 2.0 * NORM0, BOTH, True, epsilon=0.5, delta=0.2)
    torch.testing.assert_close(above, 1.2 * 0.8 * ETA0)


def test_update_bound_is_per_phase_and_skips_unvisited() -> None:
    force = torch.stack([0.1 * NORM0[0], 2.0 * NORM0[1]])
    eta = update_bound(ETA0, force, BOTH, False, epsilon=0.5, delta=0.2)
    torch.testing.assert_close(eta[0], 0.8 * ETA0[0])
    torch.testing.assert_close(eta[1], 1.2 * ETA0[1])
    eta = update_bound(ETA0, torch.zeros(2), torch.tensor([True, False]), False, 0.5, 0.2)
    torch.testing.assert_close(eta[1], ETA0[1])  # no sample: no evidence, no change
    eta = update_bound(ETA0, torch.zeros(2), torch.tensor([False, False]), True, 0.5, 0.2)
    torch.testing.assert_close(eta, 0.8 * ETA0)  # the skill decay reaches every phase


def test_curriculum_band_and_rates_are_the_papers() -> None:
    cfg = CurriculumConfig()
    assert (cfg.epsilon, cfg.delta, cfg.negligible_force_n, cfg.less_assist_progress) == (
        0.5,
        0.2,
        0.1,
        0.8,
    )


def test_less_assist_reward_switches_on_at_80_percent_and_stays_on() -> None:
    cur = AssistCurriculum(ETA0, PAPER)
    half = 0.8 * NORM0  # inside the band: bounds unchanged
    cur.update(0, half, BOTH, skill_progress=0.79)
    assert not cur.less_assist_reward
    cur.update(1, half, BOTH, skill_progress=0.8)
    assert cur.less_assist_reward
    cur.update(2, half, BOTH, skill_progress=0.3)
    assert cur.less_assist_reward
    torch.testing.assert_close(cur.eta, ETA0)


def test_negligible_force_switches_assistance_off_for_good() -> None:
    cur = AssistCurriculum(ETA0, PAPER)
    update = cur.update(0, torch.tensor([0.05, 0.09]), BOTH, skill_progress=0.0)
    assert not update.assist_enabled and not cur.assist_enabled
    eta_off = cur.eta.clone()
    cur.update(1, 2.0 * NORM0, BOTH, skill_progress=1.0)  # nothing moves once off
    assert not cur.assist_enabled
    torch.testing.assert_close(cur.eta, eta_off)


def test_force_above_threshold_keeps_assistance() -> None:
    cur = AssistCurriculum(ETA0, PAPER)
    cur.update(0, torch.tensor([0.05, 0.2]), BOTH, skill_progress=0.0)
    assert cur.assist_enabled
    cur.update(1, torch.tensor([0.05, 0.0]), torch.tensor([True, False]), skill_progress=0.0)
    assert not cur.assist_enabled  # the only visited phase had a negligible force


def test_skill_learned_decay_drives_bounds_to_zero_and_assistance_off() -> None:
    cur = AssistCurriculum(ETA0, PAPER)
    steps = 0
    while cur.assist_enabled:
        # the agent uses its whole budget (inside the band): only the extra decay shrinks eta
        cur.update(steps, torch.linalg.vector_norm(cur.eta, dim=-1), BOTH, skill_progress=1.0)
        steps += 1
        assert steps < 100
    # the largest bound norm times 0.8^k falls under 0.1 N: k = ceil(log(0.1 / max|eta0|) / log 0.8)
    expected = int(torch.ceil(torch.log(0.1 / NORM0.max()) / torch.log(torch.tensor(0.8))))
    assert steps == expected


def test_state_dict_round_trip() -> None:
    cur = AssistCurriculum(ETA0, PAPER)
    cur.update(0, 0.1 * NORM0, BOTH, skill_progress=0.9)
    state = cur.state_dict()
    other = AssistCurriculum(ETA0, PAPER)
    other.load_state_dict(state)
    torch.testing.assert_close(other.eta, cur.eta)
    assert other.less_assist_reward and other.assist_enabled and other.num_updates == 1
    with pytest.raises(ValueError, match="another task"):
        AssistCurriculum(ETA0[:1], PAPER).load_state_dict(state)


def test_bad_inputs_are_reported() -> None:
    with pytest.raises(ValueError, match="num_phases, 6"):
        AssistCurriculum(torch.ones(2, 5))
    with pytest.raises(ValueError, match=">= 0"):
        AssistCurriculum(-torch.ones(1, 6))
    with pytest.raises(ValueError, match="epsilon"):
        CurriculumConfig(epsilon=1.5)
    with pytest.raises(ValueError, match="2 phases"):
        AssistCurriculum(ETA0, PAPER).update(
            0, torch.zeros(3), torch.ones(3, dtype=torch.bool), 0.0
        )
    with pytest.raises(ValueError, match="no initial-bound row"):
        paper_bound_rows("juggle")


def test_paper_table_and_identical_bounds() -> None:
    # One table (optimal_control.bounds); the stand task's default is its walking row.
    assert STAND.default_assist_bound().tolist() == PAPER_ETA0["walk"]["all"]
    flip = torch.tensor(paper_bound_rows("backflip"))
    assert flip[2, 2] == 100.0 and flip[0, 2] == 10.0
    same = identical_axis_bounds(flip)
    torch.testing.assert_close(same[2], torch.tensor([60.0, 60.0, 60.0, 30.0, 30.0, 30.0]))
    torch.testing.assert_close(
        same[0], torch.tensor([30.0, 30.0, 30.0, 70.0 / 3, 70.0 / 3, 70.0 / 3])
    )


def test_assist_statistics_mean_norm_per_phase() -> None:
    stats = AssistStatistics(num_phases=3)
    wrench = torch.tensor([[3.0, 4.0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 2.0], [1.0, 0, 0, 0, 0, 0]])
    stats.add({"applied_wrench": wrench, "phase": torch.tensor([0, 2, 0])})
    stats.add({"applied_wrench": torch.zeros(3, 6), "phase": torch.tensor([0, 0, 0])})
    norm, visited = stats.result()
    torch.testing.assert_close(norm, torch.tensor([(5.0 + 1.0) / 5, 0.0, 2.0]))
    assert visited.tolist() == [True, False, True]
    assert stats.mean_force_n() == pytest.approx((5.0 + 0.0 + 1.0) / 3 / 2)
    stats.reset()
    assert not stats.result()[1].any()


def _step_extras(phase: list[int], force: float) -> dict:
    wrench = torch.zeros(len(phase), 6)
    wrench[:, 0] = force
    return {"applied_wrench": wrench, "phase": torch.tensor(phase)}


def test_curriculum_event_updates_once_per_rollout() -> None:
    """In-env Algorithm 1: statistics of exactly ``steps_per_iteration`` steps, one update each."""
    event = Rollout(AssistCurriculum(ETA0, PAPER), steps_per_iteration=3)
    # Phase 0 gets a small wrench (shrink), phase 1 one far above its bound (grow).
    rows = [event.on_step(_step_extras([0, 1], 0.0), 0.1) for _ in range(2)]
    assert rows == [None, None]
    big = float(NORM0[1]) * 3 * 2  # mean over the 3 phase-1 samples: 2 x the bound norm
    row = event.on_step(_step_extras([0, 1], 0.0) | {"applied_wrench": torch.tensor(
        [[0.0] * 6, [big, 0, 0, 0, 0, 0]])}, 0.4)  # fmt: skip
    assert row is not None and row["iteration"] == 0 and event.iteration == 1
    torch.testing.assert_close(torch.tensor(row["eta"][0]), ETA0[0] * 0.8)
    torch.testing.assert_close(torch.tensor(row["eta"][1]), ETA0[1] * 1.2)
    assert row["skill_progress"] == pytest.approx(0.2)
    assert event.steps == 0 and event.stats.steps == 0
    # The next rollout starts from the new bounds; state round-trips.
    state = event.state_dict()
    other = Rollout(AssistCurriculum(ETA0, PAPER), steps_per_iteration=3)
    other.load_state_dict(state)
    torch.testing.assert_close(other.curriculum.eta, event.curriculum.eta)
    assert other.history == event.history and other.iteration == 1


def test_curriculum_event_ignores_steps_while_assistance_is_off() -> None:
    curriculum = AssistCurriculum(ETA0, PAPER)
    curriculum.assist_enabled = False
    event = Rollout(curriculum, steps_per_iteration=2)
    event.on_step(_step_extras([0, 0], 50.0), 1.0)
    row = event.on_step(_step_extras([0, 0], 50.0), 1.0)
    assert row["visited"] == [False, False] and row["applied_force_n"] == 0.0
    torch.testing.assert_close(curriculum.eta, ETA0)  # switched off: bounds frozen


def _distributed_worker(rank: int, world: int, port: int, queue) -> None:
    import torch.distributed as dist

    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank,
                            world_size=world)  # fmt: skip
    try:
        event = Rollout(AssistCurriculum(ETA0, PAPER), steps_per_iteration=1)
        # Rank 0 sees a tiny wrench in phase 0 only, rank 1 a large one in phase 0 and phase 1.
        force = [1.0, 200.0][rank]
        phases = [[0, 0], [0, 1]][rank]
        row = event.on_step(_step_extras(phases, force), skill_progress=0.2 * (rank + 1))
        queue.put((rank, row))
    finally:
        dist.destroy_process_group()


def test_curriculum_statistics_are_reduced_across_processes() -> None:
    """Under torchrun every process moves its bounds identically, from the pooled statistics."""
    import socket

    import torch.multiprocessing as mp

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_distributed_worker, args=(r, 2, port, queue)) for r in (0, 1)]
    for p in procs:
        p.start()
    rows = dict(queue.get(timeout=60) for _ in procs)
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    assert rows[0]["eta"] == rows[1]["eta"]
    # pooled phase 0: samples 1, 1, 200 -> mean 67.3; phase 1: 200 (one sample)
    pooled = torch.tensor(rows[0]["applied_norm"])
    torch.testing.assert_close(pooled, torch.tensor([202.0 / 3, 200.0]))
    assert rows[0]["skill_progress"] == pytest.approx(0.3)
    # single-process view of rank 0 alone would have shrunk phase 0; pooled, it is inside the band
    torch.testing.assert_close(torch.tensor(rows[0]["eta"][0]), ETA0[0])
    torch.testing.assert_close(torch.tensor(rows[0]["eta"][1]), ETA0[1] * 1.2)


def test_rarely_visited_phases_keep_their_bound_with_min_phase_samples() -> None:
    """Option against a measured failure (backflip): a phase visited by a handful of samples
    shrinks on noise, and the squashed wrench can never exceed its bound to grow it back."""
    cfg = CurriculumConfig(min_phase_samples=3, **PAPER_RULES)
    event = Rollout(AssistCurriculum(ETA0, cfg), steps_per_iteration=1)
    row = event.on_step(_step_extras([0, 0, 0, 1], 0.0), 0.0)  # phase 1: one sample
    assert row["visited"] == [True, False]
    torch.testing.assert_close(torch.tensor(row["eta"][1]), ETA0[1])
    torch.testing.assert_close(torch.tensor(row["eta"][0]), ETA0[0] * 0.8)
    # with the paper's rule the single sample counts and shrinks phase 1 too
    paper = Rollout(AssistCurriculum(ETA0, PAPER), steps_per_iteration=1)
    torch.testing.assert_close(
        torch.tensor(paper.on_step(_step_extras([0, 0, 0, 1], 0.0), 0.0)["eta"][1]), ETA0[1] * 0.8
    )
    with pytest.raises(ValueError, match="min-phase-samples"):
        CurriculumConfig(min_phase_samples=0)


def test_histogram_quantile_is_the_upper_bin_edge() -> None:
    hist = torch.zeros(3, 10, dtype=torch.float64)
    hist[0, 0] = 8.0  # 80 % zero
    hist[0, 9] = 2.0  # 20 % saturated
    hist[1, 4] = 1.0
    torch.testing.assert_close(
        histogram_quantile(hist, 0.9), torch.tensor([1.0, 0.5, 0.0], dtype=torch.float64)
    )
    torch.testing.assert_close(
        histogram_quantile(hist, 0.5)[0], torch.tensor(0.1, dtype=torch.float64)
    )


def _as_needed_extras(num_envs: int, helped: int, eta: torch.Tensor) -> dict:
    """One step in phase 0: ``helped`` envs get the full bound (a saturated helper), the rest 0."""
    wrench = torch.zeros(num_envs, 6)
    wrench[:helped] = eta
    return {
        "applied_wrench": wrench,
        "phase": torch.zeros(num_envs, dtype=torch.long),
        "bound": eta.expand(num_envs, 6).clone(),
    }


def test_quantile_measure_keeps_the_bound_of_an_as_needed_helper() -> None:
    """The interplay of issue 13: a helper that is zero inside its tolerance band and saturates
    beyond it has a small mean |F|, so the paper's rule shrinks its bound every iteration although
    it uses all of it where help is needed; the quantile measure holds the bound while more than
    10 % of the states need it, and shrinks it once they do not."""
    eta0 = ETA0[:1]
    paper = Rollout(AssistCurriculum(eta0, PAPER), steps_per_iteration=1)
    quant = Rollout(
        AssistCurriculum(eta0, CurriculumConfig(**{**PAPER_RULES, "force_measure": "quantile"})),
        steps_per_iteration=1,
    )
    for _ in range(5):
        p_row = paper.on_step(_as_needed_extras(100, 20, paper.curriculum.eta[0]), 0.0)
        q_row = quant.on_step(_as_needed_extras(100, 20, quant.curriculum.eta[0]), 0.0)
    torch.testing.assert_close(paper.curriculum.eta, eta0 * 0.8**5)
    torch.testing.assert_close(quant.curriculum.eta, eta0)
    assert p_row["mean_applied_norm"][0] == pytest.approx(0.2 * float(NORM0[0]) * 0.8**4, rel=1e-5)
    assert q_row["applied_ratio_quantile"] == [1.0]
    # per axis: the mean |F| over the phase's samples (20 % at the full bound)
    torch.testing.assert_close(torch.tensor(q_row["applied_abs_per_axis"][0]), 0.2 * eta0[0])
    # help needed in 5 % of the states only: below the 10 % the quantile watches -> shrink
    q_row = quant.on_step(_as_needed_extras(100, 5, quant.curriculum.eta[0]), 0.0)
    torch.testing.assert_close(quant.curriculum.eta, eta0 * 0.8)
    # the histogram is checkpointed with the statistics
    quant.stats.add(_as_needed_extras(10, 10, quant.curriculum.eta[0]))
    state = quant.stats.state_dict()
    other = AssistStatistics(1)
    other.load_state_dict(state)
    torch.testing.assert_close(other.ratio_hist, quant.stats.ratio_hist)
    with pytest.raises(ValueError, match="force_measure"):
        CurriculumConfig(force_measure="median")
    with pytest.raises(ValueError, match="force-quantile"):
        CurriculumConfig(force_quantile=1.0)


def test_alone_measure_triggers_the_decay_and_helped_progress_does_not() -> None:
    cur = AssistCurriculum(ETA0, CurriculumConfig(skill_measure="alone", anneal_iterations=0))
    assert cur.cfg.alone_share > 0
    mid = 0.7 * NORM0  # inside the band: the force rule holds the bound
    cur.update(0, mid, BOTH, skill_progress=1.5, alone_progress=0.1)  # helped skill only
    torch.testing.assert_close(cur.eta, ETA0)
    cur.update(1, mid, BOTH, skill_progress=0.2, alone_progress=0.8)
    torch.testing.assert_close(cur.eta, 0.8 * ETA0)
    with pytest.raises(ValueError, match="alone envs' progress"):
        cur.update(2, mid, BOTH, skill_progress=0.2)
    with pytest.raises(ValueError, match="alone_share > 0"):
        CurriculumConfig(skill_measure="alone", alone_share=0.0)
    with pytest.raises(ValueError, match="skill_measure"):
        CurriculumConfig(skill_measure="both")


def test_event_averages_the_alone_progress_over_the_rollout() -> None:
    cfg = CurriculumConfig(skill_measure="alone")
    event = Rollout(AssistCurriculum(ETA0, cfg), steps_per_iteration=2)
    zero = {"applied_wrench": torch.zeros(2, 6), "phase": torch.zeros(2, dtype=torch.long)}
    assert event.on_step(zero, skill_progress=0.0, alone_progress=0.6) is None
    row = event.on_step(zero, skill_progress=0.0, alone_progress=1.0)
    assert row["alone_progress"] == pytest.approx(0.8) and row["skill_learned"]


def test_the_default_weans_by_the_helped_skill_under_a_200_iteration_schedule() -> None:
    cur = AssistCurriculum(ETA0)
    cfg = cur.cfg
    assert (cfg.force_measure, cfg.skill_measure, cfg.anneal_iterations) == ("none", "helped", 200)
    for it in range(3):  # an untrained head uses a tenth of its bound: the paper would shrink
        cur.update(it, 0.1 * NORM0, BOTH, skill_progress=0.59, alone_progress=1.5)
    torch.testing.assert_close(cur.eta, (1 - 3 / 200) * ETA0)  # the schedule's cap only
    cur.update(3, 0.1 * NORM0, BOTH, skill_progress=0.6)  # weaning: below the cap (1 - 4 / 200)
    torch.testing.assert_close(cur.eta, 0.8 * (1 - 3 / 200) * ETA0)
    cur.update(4, 0.1 * NORM0, BOTH, skill_progress=0.5)  # the helped skill dropped: pause
    torch.testing.assert_close(cur.eta, 0.8 * (1 - 3 / 200) * ETA0)


def test_no_force_rule_holds_the_bound_until_the_evaluation_says_learned() -> None:
    cur = AssistCurriculum(
        ETA0,
        CurriculumConfig(
            skill_measure="evaluation", skill_learned_progress=0.8, anneal_iterations=0
        ),
    )
    for it in range(3):  # an untrained head uses a tenth of its bound: the paper would shrink
        cur.update(it, 0.1 * NORM0, BOTH, skill_progress=1.5, alone_progress=1.5)
    torch.testing.assert_close(cur.eta, ETA0)
    cur.note_evaluation(0.9)
    cur.update(3, 0.1 * NORM0, BOTH, skill_progress=0.0)
    torch.testing.assert_close(cur.eta, 0.8 * ETA0)
    other = AssistCurriculum(ETA0, cur.cfg)
    other.load_state_dict(cur.state_dict())
    assert other.evaluated_progress == 0.9


def test_anneal_schedule_caps_the_bound_and_switches_assistance_off() -> None:
    cur = AssistCurriculum(ETA0, CurriculumConfig(anneal_iterations=4))
    for it in range(3):  # no rule fires (no force rule, helped skill 0): the clock alone
        cur.update(it, 0.5 * NORM0, BOTH, skill_progress=0.0)
        torch.testing.assert_close(cur.eta, ETA0 * (1.0 - (it + 1) / 4))
        assert cur.assist_enabled
    cur.update(3, 0.5 * NORM0, BOTH, skill_progress=0.0)
    assert not cur.assist_enabled and float(cur.eta.abs().max()) == 0.0
    weaned = AssistCurriculum(ETA0, CurriculumConfig(anneal_iterations=100))
    weaned.update(0, 0.5 * NORM0, BOTH, skill_progress=0.7)  # the rules go faster: they win
    torch.testing.assert_close(weaned.eta, 0.8 * ETA0)
    with pytest.raises(ValueError, match="anneal-iterations"):
        CurriculumConfig(anneal_iterations=-1)
