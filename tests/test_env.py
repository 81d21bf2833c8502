"""The batched G1 env: rsl-rl VecEnv API, partial resets, time-outs, divergence guard, randomisation."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch
from rsl_rl.env import VecEnv

from rl.envs import EnvConfig, G1VecEnv, make_env
from rl.envs.model import STATE_SPEC
from rl.envs.randomization import PARAM_NAMES
from rl.tasks import TASKS, StandTask
from robots import g1

N = 6


def quiet_env(num_envs: int = N, **overrides) -> G1VecEnv:
    """An env whose physics depends only on the actions: no pushes, randomisation or reset noise."""
    settings = dict(
        num_threads=2,
        pushes=False,
        randomize=False,
        reset_joint_pos_noise_rad=0.0,
        reset_base_vel_noise_mps=0.0,
        reset_random_yaw=False,
    )
    settings.update(overrides)
    return make_env("stand", num_envs, **settings)


def zero_actions(env: G1VecEnv) -> torch.Tensor:
    return torch.zeros(env.num_envs, env.num_actions)


def test_vecenv_api_shapes_and_dtypes():
    env = make_env("stand", N, num_threads=2)
    assert isinstance(env, VecEnv)
    assert env.num_actions == g1.NUM_JOINTS + 6 == 35
    assert env.num_phases == 1 and env.device == "cpu"
    assert env.episode_length_buf.dtype == torch.long and env.episode_length_buf.shape == (N,)
    assert env.max_episode_length == round(env.cfg.episode_length_s / 0.02)
    obs = env.get_observations()
    p = obs["policy"].shape[1]
    assert p == 3 + 3 + 3 * g1.NUM_JOINTS + env.task.command_dim
    expected = {
        "policy": p,
        "history": env.cfg.history_length * p,
        "privileged": 3 + 6 + len(PARAM_NAMES) + env.num_phases + 2,
        "base_lin_vel": 3,
        "policy_clean": p,
    }
    for name, width in expected.items():
        assert obs[name].shape == (N, width), name
    assert obs["critic"].shape[0] == N and obs["critic"].shape[1] > p + expected["privileged"]
    actions = torch.randn(N, env.num_actions)
    obs, rew, dones, extras = env.step(actions)
    for name in (*expected, "critic"):
        assert obs[name].dtype == torch.float32 and torch.isfinite(obs[name]).all(), name
    assert rew.shape == (N,) and rew.dtype == torch.float32 and torch.isfinite(rew).all()
    assert dones.shape == (N,) and dones.dtype == torch.bool
    assert extras["time_outs"].shape == (N,) and extras["time_outs"].dtype == torch.bool
    assert all(isinstance(v, float) for v in extras["log"].values())
    assert {f"Reward/{k}" for k in env.task.reward_terms()} <= set(extras["log"])
    assert "Episode/diverged_envs" in extras["log"]
    assist = extras["assist"]
    assert assist["applied_wrench"].shape == (N, 6) and assist["bound"].shape == (N, 6)
    assert assist["phase"].shape == (N,) and assist["phase"].dtype == torch.long
    assert extras["skill_progress"] >= 0.0
    # The policy observation holds the last motion action; the history ends with this observation.
    last_action = obs["policy_clean"][:, 6 + 2 * g1.NUM_JOINTS : 6 + 3 * g1.NUM_JOINTS]
    applied = actions[:, : g1.NUM_JOINTS].clamp(-env.cfg.clip_actions, env.cfg.clip_actions)
    not_reset = ~dones
    assert torch.allclose(last_action[not_reset], applied[not_reset])
    assert torch.equal(obs["history"][:, -p:], obs["policy"])
    env.close()


def test_observation_noise_only_on_policy_group():
    env = make_env("stand", N, num_threads=1, randomize=False)
    obs = env.get_observations()
    assert not torch.equal(obs["policy"], obs["policy_clean"])
    assert (obs["policy"] - obs["policy_clean"]).abs().max() <= env.cfg.noise_joint_vel_rps
    quiet = quiet_env(noise=False)
    obs = quiet.get_observations()
    assert torch.equal(obs["policy"], obs["policy_clean"])


def test_partial_reset_only_resets_done_envs():
    env, untouched = quiet_env(), quiet_env()
    for _ in range(3):
        env.step(zero_actions(env))
        untouched.step(zero_actions(untouched))
    fallen = 2
    z = env.layout.qpos.start + 2
    env.state[fallen, z] = 0.2  # pelvis on the floor: a fall
    _, _, dones, _ = env.step(zero_actions(env))
    untouched.step(zero_actions(untouched))
    # Only the fallen env is done and reset, to the standing keyframe.
    assert dones.tolist() == [i == fallen for i in range(N)]
    assert env.episode_length_buf[fallen] == 0
    others = np.arange(N) != fallen
    assert (env.episode_length_buf[others] == 4).all()
    assert env.state[fallen, z] == pytest.approx(env.layout.stand_state[z])
    # Every other row is bit-identical to an env where nothing was reset.
    np.testing.assert_array_equal(env.state[others], untouched.state[others])


def test_time_outs_at_max_episode_length():
    env = quiet_env(episode_length_s=0.1)  # 5 policy steps
    assert env.max_episode_length == 5
    for step in range(1, 6):
        _, _, dones, extras = env.step(zero_actions(env))
        if step < 5:
            assert not dones.any() and not extras["time_outs"].any()
    assert extras["time_outs"].all() and dones.all()
    assert (env.episode_length_buf == 0).all()
    # A survived episode counts toward the stand task's skill progress.
    assert extras["skill_progress"] == pytest.approx(1.0 / env.task.cfg.target_survival)


def test_time_outs_of_shortened_episodes_do_not_count_as_survival():
    """Runners start episode_length_buf at random values: those first episodes time out early
    and must not look like a learned skill."""
    env = quiet_env(episode_length_s=0.2)
    env.episode_length_buf = torch.full_like(env.episode_length_buf, env.max_episode_length - 1)
    _, _, dones, extras = env.step(zero_actions(env))
    assert extras["time_outs"].all() and dones.all()
    assert extras["skill_progress"] == 0.0


def test_nan_state_is_detected_reset_and_counted():
    env = quiet_env()
    env.step(zero_actions(env))
    env.state[1, env.layout.qvel.start + 8] = np.nan
    env.state[4, env.layout.qvel.start + 2] = 1e6  # blows up inside the physics step
    obs, rew, dones, extras = env.step(zero_actions(env))
    assert dones[1] and dones[4]
    assert not extras["time_outs"][1] and not extras["time_outs"][4]
    assert dones.sum() == 2
    assert extras["log"]["Episode/diverged_envs"] == 2.0 and env.diverged_total == 2
    assert np.isfinite(env.state).all()
    assert all(torch.isfinite(v).all() for v in obs.values())
    assert torch.isfinite(rew).all() and rew[1] == 0.0
    assert env.episode_length_buf[1] == 0 and env.episode_length_buf[0] == 2
    actions = zero_actions(env)
    actions[3, 0] = float("nan")
    _, _, dones, extras = env.step(actions)  # and the run goes on; bad actions are counted
    assert extras["log"]["Episode/nonfinite_action_envs"] == 1.0
    assert extras["log"]["Episode/diverged_envs"] == 0.0 and not dones.any()


def test_randomisation_params_in_privileged_obs_and_physics():
    env = make_env("stand", 8, num_threads=1, seed=3)
    params = env.randomization_params
    assert params.shape == (8, len(PARAM_NAMES))
    assert params[:, 1].std() > 0  # payloads differ between envs
    privileged = env.get_observations()["privileged"]
    torch.testing.assert_close(privileged[:, 9 : 9 + len(PARAM_NAMES)], params)
    body = env.model.body(env.cfg.payload_body).id
    sole = env.model.geom("left_sole_0").id
    for i in range(8):
        model = env.models[i]
        # Gravity on the free joint (MuJoCo's bias force at rest) weighs the payload.
        data = mujoco.MjData(model)
        mujoco.mj_setState(model, data, env.layout.stand_state, STATE_SPEC)
        mujoco.mj_forward(model, data)
        expected_mass = env.total_mass_kg + float(params[i, 1])
        assert data.qfrc_bias[2] == pytest.approx(
            expected_mass * model.opt.gravity[2] * -1, rel=1e-6
        )
        assert model.geom_friction[sole, 0] == pytest.approx(float(params[i, 0]))
        np.testing.assert_allclose(
            model.body_ipos[body] - env.model.body_ipos[body], params[i, 2:].numpy(), atol=1e-6
        )
    # Resampled at reset: the params of a reset env change, the others stay.
    before = params.clone()
    env.state[0, env.layout.qpos.start + 2] = 0.1
    env.step(zero_actions(env))
    assert not torch.equal(env.randomization_params[0], before[0])
    torch.testing.assert_close(env.randomization_params[1:], before[1:])


def test_pushes_kick_the_base():
    env = quiet_env(pushes=True, push_interval_range_s=(0.02, 0.02), push_velocity_xy_mps=1.0)
    still = quiet_env()
    env.step(zero_actions(env))
    still.step(zero_actions(still))
    speed = np.linalg.norm(env.state[:, env.layout.qvel][:, :2], axis=1)
    still_speed = np.linalg.norm(still.state[:, still.layout.qvel][:, :2], axis=1)
    assert (speed > still_speed + 0.05).all()


class CrouchStartStand(StandTask):
    """A task variant through the hooks only: start 5 cm lower with the knees bent more."""

    def reset_state(self, env_ids, qpos, qvel):
        qpos[:, 2] -= 0.05
        qpos[:, 7 + g1.JOINT_NAMES.index("left_knee_joint")] += 0.3


def test_tasks_plug_in_through_hooks():
    env = G1VecEnv(EnvConfig(num_envs=3, num_threads=1, randomize=False), CrouchStartStand())
    stand_z = env.layout.stand_state[env.layout.qpos.start + 2]
    np.testing.assert_allclose(env.env_state.base_pos_w[:, 2].numpy(), stand_z - 0.05, atol=1e-6)
    knee = g1.JOINT_NAMES.index("left_knee_joint")
    assert (env.env_state.joint_pos_rad[:, knee] > g1.STAND_JOINT_POS_RAD[knee] + 0.2).all()


def test_bad_inputs_give_clear_errors():
    with pytest.raises(ValueError, match="Unknown task"):
        make_env("moonwalk", 2)
    with pytest.raises(ValueError, match="not EnvConfig fields"):
        make_env("stand", 2, num_env=3)
    with pytest.raises(ValueError, match="num_envs"):
        EnvConfig(num_envs=0)
    with pytest.raises(ValueError, match="payload_body"):
        G1VecEnv(EnvConfig(num_envs=1, payload_body="backpack"), StandTask())
    with pytest.raises(ValueError, match="payload_mass_range_kg"):
        make_env("stand", 1, payload_mass_range_kg=(-20.0, 0.0))
    env = make_env("stand", 2, num_threads=1)
    with pytest.raises(ValueError, match=r"actions of shape \(2, 35\)"):
        env.step(torch.zeros(2, 29))
    with pytest.raises(ValueError, match="num_phases, 6"):
        env.set_assist_bound(torch.ones(2, 6))
    with pytest.raises(ValueError, match="zeta"):
        env.set_random_mask_prob(1.5)
    assert "stand" in TASKS


def test_bench_env_smoke():
    from a2cf_mb.bench.env import EnvBenchConfig, format_results, run_env_benchmark

    cfg = EnvBenchConfig(num_envs=(4,), num_steps=5, warmup_steps=1, repeats=1, num_threads=1)
    results = run_env_benchmark(cfg)
    figures = results["sizes"]["4"]
    assert figures["env_steps_per_s"] > 0 and figures["physics_env_steps_per_s"] > 0
    assert figures["env_over_physics"] > 0
    assert "env/physics" in format_results(results)
