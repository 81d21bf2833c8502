"""The runner, checkpoints and the in-env curriculum on a cheap dummy env (rsl_rl's test style):
no physics, so every plumbing rule is checked in a fraction of a second."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace
from typing import Any

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from rl.a2cf.algorithm1 import Algorithm1, RecordingEnv
from rl.a2cf.config import PAPER_RULES, CurriculumConfig, get_mode
from rl.a2cf.curriculum import AssistCurriculum
from rl.runs.folder import CHECKPOINT_DIR, CURRICULUM_LOG, LAST_CHECKPOINT
from rl.training.config import ModelConfig, PPOConfig, TrainConfig
from rl.training.runner import A2CFRunner, rsl_rl_config

P, H, PRIV, N, STEPS = 5, 3, 4, 8, 6
ETA0 = torch.tensor([[20.0, 20.0, 20.0, 5.0, 5.0, 5.0]])


class DummyAssistEnv(VecEnv):
    """Observation groups of the A2CF contract, reward = -|motion action|^2, episodes of 10 steps;
    the applied wrench is eta * tanh(raw) as in the real env; Algorithm 1 is the runner's."""

    def __init__(self, seed: int = 0) -> None:
        self.num_envs, self.num_actions, self.max_episode_length = N, 29 + 6, 10
        self.device, self.cfg = "cpu", {"dummy": True}
        self.generator = torch.Generator().manual_seed(seed)
        self.episode_length_buf = torch.zeros(N, dtype=torch.long)
        self.bound = ETA0.clone()
        self.assist = SimpleNamespace(alone=torch.zeros(N, dtype=torch.bool))
        self.task = SimpleNamespace(phase_names=("all",))
        self._obs = self._observe()

    def _observe(self) -> TensorDict:
        policy = torch.randn(N, P, generator=self.generator)
        return TensorDict(
            {
                "policy": policy,
                "history": policy.repeat(1, H),
                "privileged": torch.randn(N, PRIV, generator=self.generator),
                "critic": torch.randn(N, P + PRIV, generator=self.generator),
                "base_lin_vel": torch.zeros(N, 3),
                "policy_clean": policy,
            },
            batch_size=[N],
        )

    def set_assist_bound(self, eta: torch.Tensor) -> None:
        self.bound = eta.clone()

    def set_assist_enabled(self, enabled: bool) -> None:
        pass

    def set_less_assist_reward(self, enabled: bool) -> None:
        pass

    def use_alone_envs(self, share: float, window: int) -> None:
        assert share == 0.0

    def get_observations(self) -> TensorDict:
        return self._obs

    def step(self, actions: torch.Tensor):
        wrench = self.bound * torch.tanh(actions[:, 29:])
        reward = -actions[:, :29].square().mean(dim=-1)
        self.episode_length_buf += 1
        time_outs = self.episode_length_buf >= self.max_episode_length
        self.episode_length_buf[time_outs] = 0
        self._obs = self._observe()
        log: dict[str, float] = {"Train/mean_step_reward": float(reward.mean())}
        assist = {"applied_wrench": wrench, "phase": torch.zeros(N, dtype=torch.long)}
        extras = {"time_outs": time_outs, "log": log, "assist": assist, "skill_progress": 0.5}
        return self._obs, reward, time_outs, extras

    def state_dict(self) -> dict[str, Any]:
        return {
            "generator": self.generator.get_state(),
            "episode_length_buf": self.episode_length_buf.clone(),
            "obs": self._obs.clone(),
            "bound": self.bound.clone(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.generator.set_state(state["generator"])
        self.episode_length_buf = state["episode_length_buf"].clone()
        self._obs = state["obs"].clone()
        self.bound = state["bound"].clone()


CFG = TrainConfig(
    num_steps_per_env=STEPS,
    ppo=PPOConfig(gamma=0.995, num_learning_epochs=1, num_mini_batches=2, assist_init_noise_std=0.05),
    model=ModelConfig(motion_hidden_dims=(8,), assist_hidden_dims=(8,), critic_hidden_dims=(8,),
                      encoder_hidden_dims=(8,), latent_dim=2, vae_learning_epochs=1),
)  # fmt: skip


def make_runner(run_dir, total: int, keep: int = 2) -> tuple[DummyAssistEnv, A2CFRunner]:
    torch.manual_seed(0)
    env = DummyAssistEnv()
    curriculum = AssistCurriculum(ETA0, CurriculumConfig(**PAPER_RULES))
    env.set_assist_bound(curriculum.eta)
    learner = RecordingEnv(env, Algorithm1(curriculum))
    runner = A2CFRunner(learner, rsl_rl_config(CFG, get_mode("a2cf")), run_dir, get_mode("a2cf"),
                        total_iterations=total, keep_interval=keep)  # fmt: skip
    return env, runner


def test_rsl_rl_loop_drives_the_curriculum_once_per_iteration(tmp_path) -> None:
    env, runner = make_runner(tmp_path, total=3)
    runner.learn(3)
    log = [json.loads(line) for line in (tmp_path / CURRICULUM_LOG).read_text().splitlines()]
    assert [row["iteration"] for row in log] == [0, 1, 2]
    # a near-silent head applies far less than half the bound: each update shrinks it by 0.8
    for k, row in enumerate(log, start=1):
        torch.testing.assert_close(torch.tensor(row["eta"]), ETA0 * 0.8**k)
    torch.testing.assert_close(env.bound, ETA0 * 0.8**3)
    assert [r["iteration"] for r in runner.history] == [0, 1, 2]
    assert all(r["applied_force_n"] > 0 for r in runner.history)
    files = sorted(p.name for p in (tmp_path / CHECKPOINT_DIR).iterdir())
    assert files == ["last.pt", "model_2.pt", "model_3.pt"]  # every 2nd and the last one
    state = torch.load(tmp_path / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    assert state["completed_iterations"] == 3 and state["a2cf"]["iteration"] == 3


def test_checkpoint_resume_matches_the_uninterrupted_loop(tmp_path) -> None:
    _, whole = make_runner(tmp_path / "whole", total=4)
    whole.learn(4)
    _, first = make_runner(tmp_path / "part", total=4)
    first.learn(2)
    env, resumed = make_runner(tmp_path / "part", total=4)
    resumed.load_checkpoint(tmp_path / "part" / CHECKPOINT_DIR / LAST_CHECKPOINT)
    assert resumed.completed_iterations == 2 and resumed.algorithm1.iteration == 2
    resumed.learn(2)
    keys = ("mean_step_reward", "applied_force_n", "losses", "eta_norm")
    assert [{k: r[k] for k in keys} for r in whole.history] == [
        {k: r[k] for k in keys} for r in resumed.history
    ]
    a = torch.load(tmp_path / "whole" / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    b = torch.load(tmp_path / "part" / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    for name, value in a["actor_state_dict"].items():
        assert torch.equal(value, b["actor_state_dict"][name]), name
    same_log = (tmp_path / "whole" / CURRICULUM_LOG).read_text()
    assert same_log == (tmp_path / "part" / CURRICULUM_LOG).read_text()


def test_old_checkpoints_are_refused_with_a_clear_message(tmp_path) -> None:
    import pytest

    _, runner = make_runner(tmp_path, total=1)
    runner.learn(1)
    path = tmp_path / CHECKPOINT_DIR / LAST_CHECKPOINT
    state = torch.load(path, weights_only=False)
    state.pop("format")
    torch.save(state, path)
    with pytest.raises(ValueError, match="older layout"):
        make_runner(tmp_path, total=1)[1].load_checkpoint(path)
    assert dataclasses.asdict(CFG)["num_steps_per_env"] == STEPS


def test_a_checkpoint_of_format_3_is_migrated_or_refused() -> None:
    """Format 3 held Algorithm 1 inside the env's assist part (and a second copy beside it);
    format 4 holds it once, under ``a2cf``. One saved inside a rollout cannot be continued."""
    import pytest

    from rl.training.runner import migrate_checkpoint

    event = {"curriculum": {"eta": ETA0}, "iteration": 7, "step_in_iteration": 0,
             "skill_sum": 0.0, "alone_sum": 0.0, "stats": {"steps": 0}, "history": [{"k": 1}]}  # fmt: skip
    old = {"format": 3, "curriculum": {"eta": ETA0}, "env": {"assist": {"bound": ETA0,
           "curriculum_event": event}}}  # fmt: skip
    new = migrate_checkpoint(old)
    assert new["format"] == 4 and "curriculum" not in new
    assert "curriculum_event" not in new["env"]["assist"]
    assert new["a2cf"]["iteration"] == 7 and new["a2cf"]["steps"] == 0
    assert new["a2cf"]["history"] == [{"k": 1}]
    inside = {
        "format": 3,
        "env": {"assist": {"curriculum_event": {**event, "step_in_iteration": 2}}},
    }
    with pytest.raises(ValueError, match="inside a rollout"):
        migrate_checkpoint(inside)
    assert migrate_checkpoint({"format": 4, "x": 1}) == {"format": 4, "x": 1}
