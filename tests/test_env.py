"""The batched G1 env: rsl-rl VecEnv API, named observation terms, partial resets, time-outs,
divergence guard, randomisation, tasks plugging in by config, exact state round trip."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest
import torch
from rsl_rl.env import VecEnv
from stand_envs import stand_env

from rl.envs.config import EnvConfig
from rl.envs.model import STATE_SPEC
from rl.envs.randomization import PARAM_NAMES
from rl.envs.task_schema import InitialStateConfig, quiet
from rl.envs.terms import ObsTerm, RewardTerm, TerminationTerm
from rl.envs.vec_env import G1VecEnv
from rl.tasks import observations, rewards
from rl.tasks.registry import TASKS, describe_tasks, get_task, make_env, register_task
from rl.tasks.stand.task import STAND
from robots import g1

N = 6


def quiet_env(num_envs: int = N, task=None, **env_fields) -> G1VecEnv:
    """An env whose physics depends only on the actions: no pushes, randomisation or noise."""
    return make_env(quiet(task or STAND), num_envs, num_threads=2, **env_fields)


def variant(task=STAND, **changes):
    """A task variant: ``pushes=dict(...)`` etc. replace fields of the nested configs."""
    values = {}
    for name, value in changes.items():
        current = getattr(task, name)
        values[name] = dataclasses.replace(current, **value) if isinstance(value, dict) else value
    return dataclasses.replace(task, **values)


def zero_actions(env: G1VecEnv) -> torch.Tensor:
    return torch.zeros(env.num_envs, env.num_actions)


def test_vecenv_api_shapes_and_dtypes():
    env = make_env("stand", N, num_threads=2)
    assert isinstance(env, VecEnv)
    assert env.num_actions == g1.NUM_JOINTS + 6 == 35
    assert env.num_phases == 1 and env.device == "cpu"
    assert env.episode_length_buf.dtype == torch.long and env.episode_length_buf.shape == (N,)
    assert env.max_episode_length == round(env.task.episode_length_s / 0.02)
    obs = env.get_observations()
    p = obs["policy"].shape[1]
    # gyro, gravity, joint positions, velocities, last action, command, the velocity estimate
    assert p == 3 + 3 + 3 * g1.NUM_JOINTS + env.task.commands.dim + 3
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
    assert {f"Reward/{t.name}" for t in env.task.rewards} <= set(extras["log"])
    assert {f"Termination/{t.name}" for t in env.task.terminations} <= set(extras["log"])
    assert "Episode/diverged_envs" in extras["log"]
    assist = extras["assist"]
    assert assist["applied_wrench"].shape == (N, 6) and assist["bound"].shape == (N, 6)
    assert assist["phase"].shape == (N,) and assist["phase"].dtype == torch.long
    assert extras["skill_progress"] >= 0.0
    # The policy observation holds the last motion action; the history ends with this observation.
    last_action = env.observation_term("policy_clean", "last_action")
    applied = actions[:, : g1.NUM_JOINTS].clamp(-env.cfg.clip_actions, env.cfg.clip_actions)
    not_reset = ~dones
    assert torch.allclose(last_action[not_reset], applied[not_reset])
    assert torch.equal(obs["history"][:, -p:], obs["policy"])
    env.close()


def test_observation_terms_by_name():
    env = stand_env(N, num_threads=1, randomize=False)
    s = env.env_state
    torch.testing.assert_close(
        env.observation_term("policy_clean", "joint_pos"), s.joint_pos_rad - s.default_joint_pos_rad
    )
    torch.testing.assert_close(env.observation_term("privileged", "assist_bound"), s.assist_bound)
    torch.testing.assert_close(
        env.observation_term("critic", "feet_pos"), observations.feet_pos_b(s)
    )
    torch.testing.assert_close(
        env.observation_term("critic", "joint_torque"), s.joint_torque_nm / s.effort_limit_nm
    )
    names = [name for name, _, _ in env.observation_layout()["policy"]]
    assert names == ["base_ang_vel", "projected_gravity", "joint_pos", "joint_vel", "last_action",
                     "command", "base_lin_vel"]  # fmt: skip
    with pytest.raises(KeyError, match="no term 'nope'"):
        env.observation_term("policy", "nope")


def test_observation_noise_per_term_only_on_policy_group():
    env = stand_env(N, num_threads=1, randomize=False)
    obs = env.get_observations()
    assert not torch.equal(obs["policy"], obs["policy_clean"])
    for term in STAND.observations.policy.terms:
        width = env.observation_term("policy", term.name).shape[1]
        if not width:
            continue
        noise = env.observation_term("policy", term.name) - env.observation_term(
            "policy_clean", term.name
        )
        assert noise.abs().max() <= term.noise + 1e-6, term.name
        assert (noise.abs().max() > 0.3 * term.noise) == (term.noise > 0), term.name
    silent = make_env(STAND, N, num_threads=1, noise=False)
    obs = silent.get_observations()
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
    env = quiet_env(task=variant(episode_length_s=0.1))  # 5 policy steps
    assert env.max_episode_length == 5
    for step in range(1, 6):
        _, _, dones, extras = env.step(zero_actions(env))
        if step < 5:
            assert not dones.any() and not extras["time_outs"].any()
    assert extras["time_outs"].all() and dones.all()
    assert (env.episode_length_buf == 0).all()
    # A survived episode counts toward the stand task's skill progress.
    assert extras["skill_progress"] == pytest.approx(1.0 / env.task.skill.target_survival)


def test_time_outs_of_shortened_episodes_do_not_count_as_survival():
    """Runners start episode_length_buf at random values: those first episodes time out early
    and must not look like a learned skill."""
    env = quiet_env(task=variant(episode_length_s=0.2))
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
    torch.testing.assert_close(env.observation_term("privileged", "randomization"), params)
    body = env.model.body(env.task.randomization.payload_body).id
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
    pushed = variant(
        quiet(STAND), pushes=dict(enabled=True, interval_range_s=(0.02, 0.02), velocity_xy_mps=1.0)
    )
    env = make_env(pushed, N, num_threads=2)
    still = quiet_env()
    env.step(zero_actions(env))
    still.step(zero_actions(still))
    speed = np.linalg.norm(env.state[:, env.layout.qvel][:, :2], axis=1)
    still_speed = np.linalg.norm(still.state[:, still.layout.qvel][:, :2], axis=1)
    assert (speed > still_speed + 0.05).all()


def test_training_can_push_harder_than_the_evaluations_judge():
    """train_velocity_xy_mps sets the training pushes; an evaluation (env.for_evaluation) pushes
    at velocity_xy_mps, the strength the skill is judged at."""
    pushed = variant(
        quiet(STAND),
        pushes=dict(
            enabled=True, interval_range_s=(0.02, 0.02), velocity_xy_mps=0.2,
            train_velocity_xy_mps=1.5,
        ),
    )  # fmt: skip

    def largest_kick(evaluation: bool) -> float:
        env = make_env(pushed, 16, num_threads=2, seed=3)
        if evaluation:
            env.for_evaluation()
        env.step(zero_actions(env))
        return float(np.abs(env.state[:, env.layout.qvel][:, :2]).max())

    assert largest_kick(evaluation=False) > 0.8
    assert largest_kick(evaluation=True) < 0.2 + 0.05
    with pytest.raises(ValueError, match="--task-pushes-train-velocity-xy-mps"):
        variant(STAND, pushes=dict(train_velocity_xy_mps=-1.0))


def test_training_can_aim_the_pushes_backwards():
    """train_backward_share 1: every training kick pushes the robot backwards along its heading
    (random yaw), sideways parts kept; an evaluation pushes uniformly again."""
    pushed = variant(
        quiet(STAND),
        pushes=dict(
            enabled=True, interval_range_s=(0.02, 0.02), velocity_xy_mps=1.0,
            train_backward_share=1.0,
        ),
        initial_state=dict(random_yaw=True),
    )  # fmt: skip

    def forward_kicks(evaluation: bool) -> np.ndarray:
        env = make_env(pushed, 32, num_threads=2, seed=4)
        if evaluation:
            env.for_evaluation()
        env.step(zero_actions(env))
        return env.env_state.base_lin_vel_b[:, 0].numpy()

    assert (forward_kicks(evaluation=False) < 0.02).all()
    uniform = forward_kicks(evaluation=True)
    assert (uniform > 0.1).sum() > 5 and (uniform < -0.1).sum() > 5
    with pytest.raises(ValueError, match="--task-pushes-train-backward-share"):
        variant(STAND, pushes=dict(train_backward_share=1.5))


def crouch_start(env_ids, qpos, qvel, generator):
    """Start 5 cm lower with the left knee bent more (an initial-state hook)."""
    qpos[:, 2] -= 0.05
    qpos[:, 7 + g1.JOINT_NAMES.index("left_knee_joint")] += 0.3


def knee_bend(s, joint: str = "left_knee_joint"):
    """A test-only reward term: the left knee angle [rad]."""
    return s.joint_pos_rad[:, g1.JOINT_NAMES.index(joint)]


def test_a_task_plugs_in_by_config_without_touching_env_or_runner(tmp_path):
    """A new task is a config plus a registry entry: here a test-only one, trained end to end."""
    from rl.training.config import ModelConfig, PPOConfig, TrainConfig
    from rl.training.runner import train

    crouch = dataclasses.replace(
        STAND,
        name="crouch_test",
        description="test-only: stand from a crouch",
        initial_state=InitialStateConfig(reset_state=crouch_start, random_yaw=False),
        rewards=STAND.rewards + (RewardTerm("knee_bend", knee_bend, weight=0.5),),
        terminations=(
            TerminationTerm("too_low", STAND.terminations[0].func, params={"min_height_m": 0.3}),
        ),  # fmt: skip
        observations=dataclasses.replace(
            STAND.observations,
            privileged=dataclasses.replace(
                STAND.observations.privileged,
                terms=STAND.observations.privileged.terms
                + (ObsTerm("knee", lambda s: knee_bend(s).unsqueeze(-1)),),
            ),
        ),
    )
    register_task(crouch)
    try:
        env = make_env("crouch_test", 3, num_threads=1)
        stand_z = env.layout.stand_state[env.layout.qpos.start + 2]
        np.testing.assert_allclose(
            env.env_state.base_pos_w[:, 2].numpy(), stand_z - 0.05, atol=1e-6
        )
        knee = g1.JOINT_NAMES.index("left_knee_joint")
        assert (env.env_state.joint_pos_rad[:, knee] > g1.STAND_JOINT_POS_RAD[knee] + 0.2).all()
        torch.testing.assert_close(
            env.observation_term("privileged", "knee")[:, 0], env.env_state.joint_pos_rad[:, knee]
        )
        _, _, _, extras = env.step(zero_actions(env))
        assert "Reward/knee_bend" in extras["log"] and "Termination/tilted" not in extras["log"]
        assert any(r["name"] == "crouch_test" for r in describe_tasks())
        tiny = TrainConfig(
            task="crouch_test", iterations=1, num_steps_per_env=4, out=str(tmp_path),
            env=EnvConfig(num_envs=2, num_threads=1), export_onnx=False,
            ppo=PPOConfig(num_learning_epochs=1, num_mini_batches=1),
            model=ModelConfig(motion_hidden_dims=(8,), assist_hidden_dims=(8,),
                              critic_hidden_dims=(8,), encoder_hidden_dims=(8,), latent_dim=2),
        )  # fmt: skip
        result = train(tiny, verbose=False)
        assert result.iterations_done == 1
    finally:
        TASKS.pop("crouch_test")


def test_task_overrides_and_bad_task_configs():
    task = STAND.with_overrides(
        {"pushes.velocity_xy_mps": 0.3, "reward_weights": {"upright": 2.0},
         "term_params": {"tilted": {"max_tilt_rad": 0.6}}}
    )  # fmt: skip
    assert task.pushes.velocity_xy_mps == 0.3
    assert {t.name: t.weight for t in task.rewards}["upright"] == 2.0
    assert {t.name: t for t in task.terminations}["tilted"].params == {"max_tilt_rad": 0.6}
    assert STAND.pushes.velocity_xy_mps == 0.5  # variants never edit the base
    with pytest.raises(ValueError, match="no reward term"):
        STAND.with_reward_weights({"uprite": 1.0})
    with pytest.raises(ValueError, match="no parameter"):
        STAND.with_term_params({"tilted": {"max_tilt": 1.0}})
    with pytest.raises(ValueError, match="no field 'pushs'"):
        STAND.with_overrides({"pushs.enabled": False})
    with pytest.raises(ValueError, match="appears twice"):
        dataclasses.replace(STAND, rewards=STAND.rewards + (RewardTerm("alive", rewards.alive),))
    with pytest.raises(ValueError, match="one 6-D row per phase"):
        dataclasses.replace(STAND, assist_bound=((1.0,) * 6,) * 2)


def test_shared_randomisation_groups_bound_the_model_copies():
    """model_groups = G: G model copies for N envs (memory), env i on copy i % G."""
    env = make_env(variant(randomization=dict(model_groups=2)), 6, num_threads=1, seed=2)
    assert len({id(m) for m in env.models}) == 2
    assert env.models[0] is env.models[2] and env.models[1] is env.models[3]
    params = env.randomization_params
    torch.testing.assert_close(params[0], params[2])
    assert not torch.equal(params[0], params[1])
    sole = env.model.geom("left_sole_0").id
    assert env.models[1].geom_friction[sole, 0] == pytest.approx(float(params[1, 0]))
    env.state[0, env.layout.qpos.start + 2] = 0.1  # a reset keeps the group's parameters
    env.step(zero_actions(env))
    torch.testing.assert_close(env.randomization_params, params)


def test_state_dict_continues_bit_for_bit():
    """Saved mid-run and loaded into a fresh env, the next steps equal the uninterrupted run."""
    env = make_env("stand", 4, num_threads=1, seed=5)
    generator = torch.Generator().manual_seed(0)
    actions = [0.8 * torch.randn(4, 35, generator=generator) for _ in range(40)]
    for a in actions[:20]:
        env.step(a)
    saved = env.state_dict()
    fresh = make_env("stand", 4, num_threads=1, seed=99)
    fresh.load_state_dict(saved)
    for a in actions[20:]:
        obs_a, rew_a, done_a, _ = env.step(a)
        obs_b, rew_b, done_b, _ = fresh.step(a)
        assert torch.equal(rew_a, rew_b) and torch.equal(done_a, done_b)
        for key in obs_a.keys():  # noqa: SIM118 - TensorDict keys
            assert torch.equal(obs_a[key], obs_b[key]), key
    np.testing.assert_array_equal(env.state, fresh.state)
    assert env.diverged_total == fresh.diverged_total
    with pytest.raises(ValueError, match="resume with the run's own config"):
        make_env("stand", 3, num_threads=1).load_state_dict(saved)


def test_bad_inputs_give_clear_errors():
    with pytest.raises(ValueError, match="unknown task"):
        make_env("moonwalk", 2)
    with pytest.raises(ValueError, match="not EnvConfig fields"):
        make_env("stand", 2, num_env=3)
    with pytest.raises(ValueError, match="--env-num-envs"):
        EnvConfig(num_envs=0)
    with pytest.raises(ValueError, match="payload_body"):
        make_env(variant(randomization=dict(payload_body="backpack")), 1)
    with pytest.raises(ValueError, match="payload_mass_range_kg"):
        make_env(variant(randomization=dict(payload_mass_range_kg=(-20.0, 0.0))), 1)
    with pytest.raises(ValueError, match="interval-range-s"):
        variant(pushes=dict(interval_range_s=(0.0, 1.0)))
    with pytest.raises(ValueError, match="already registered"):
        register_task(STAND)
    env = make_env("stand", 2, num_threads=1)
    with pytest.raises(ValueError, match=r"actions of shape \(2, 35\)"):
        env.step(torch.zeros(2, 29))
    with pytest.raises(ValueError, match="num_phases, 6"):
        env.set_assist_bound(torch.ones(2, 6))
    with pytest.raises(ValueError, match="zeta"):
        env.set_random_mask_prob(1.5)
    assert get_task("stand") is STAND


def test_bench_env_smoke():
    from a2cf_mb.bench.env import EnvBenchConfig, format_results, run_env_benchmark

    cfg = EnvBenchConfig(num_envs=(4,), num_steps=5, warmup_steps=1, repeats=1, num_threads=1)
    results = run_env_benchmark(cfg)
    assert set(results["sizes"]) == {"4 links on", "4 links off"}
    figures = results["sizes"]["4 links on"]
    assert figures["env_steps_per_s"] > 0 and figures["physics_env_steps_per_s"] > 0
    assert figures["env_over_physics"] > 0
    assert "env/physics" in format_results(results)


def test_link_ground_contacts_and_foot_timers_from_the_physics():
    """A robot dropped onto its knees reports knee-ground contacts; a lifted robot's feet count
    air time and report the touch-down."""
    from rl.tasks import terminations

    kneel = variant(quiet(STAND), terminations=(
        TerminationTerm("link_on_ground", terminations.link_on_ground,
                        params={"bodies": ("left_knee_link", "right_knee_link")}),
    ))  # fmt: skip
    env = make_env(kneel, 2, num_threads=1)
    z = env.layout.qpos.start + 2
    env.state[1, z] = 0.3  # knees below the floor level of the standing robot
    _, _, dones, extras = env.step(zero_actions(env))
    assert extras["log"]["Termination/link_on_ground"] == 0.5 and dones.tolist() == [False, True]
    env = quiet_env(1)
    env.state[0, z] += 0.15
    env.physics.refresh_sensors(torch.arange(1))
    air = []
    for _ in range(20):
        env.step(zero_actions(env))
        air.append(env.env_state.foot_air_time_s[0].clone())
        if env.env_state.foot_first_contact.any():
            break
    assert env.env_state.foot_first_contact.any(), "the feet never touched down"
    assert air[-2].min() > 0.1  # fell about 0.15 m: ~0.17 s in the air
    landed = env.env_state.foot_first_contact[0]
    torch.testing.assert_close(
        env.env_state.foot_last_air_time_s[0][landed], air[-2][landed] + 0.02
    )


def test_alone_envs_get_no_help_and_feed_their_own_skill_window():
    """The curriculum's alone share: fixed envs whose wrench is zero for whole episodes, their
    episodes measured apart, and left out of the force rule's statistics."""
    from rl.a2cf.algorithm1 import Algorithm1, RecordingEnv
    from rl.a2cf.config import CurriculumConfig
    from rl.a2cf.curriculum import AssistCurriculum

    env = quiet_env(num_envs=8, task=variant(episode_length_s=0.06))  # 3 policy steps
    cfg = CurriculumConfig(alone_share=0.25, alone_window=4)
    eta0 = torch.full((env.num_phases, 6), 20.0)
    learner = RecordingEnv(env, Algorithm1(AssistCurriculum(eta0, cfg)))
    env.set_random_mask_prob(0.0)
    assert env.assist.alone.tolist() == [True, True] + [False] * 6
    actions = zero_actions(env)
    actions[:, 29:] = 1.0  # the head asks for help everywhere
    env.episode_length_buf = torch.zeros_like(env.episode_length_buf)
    env.episode_length_buf[6:] = env.max_episode_length - 1  # cut short: counted by nobody
    for _ in range(3):
        _, _, dones, extras = learner.step(actions)
        wrench = extras["assist"]["applied_wrench"]
        assert (wrench[:2] == 0).all() and (wrench[2:].abs() > 0).all()
        # What the critic and the assist head see: no bound where no help comes.
        bound = env.env_state.assist_bound
        assert (bound[:2] == 0).all() and (bound[2:] == 20.0).all()
    assert dones[:6].all()
    # Two alone episodes and four helped ones survived to the time limit.
    assert env.task_components.alone_skill.window.count == 2
    assert env.skill.window.count == 4
    assert extras["skill_progress_alone"] == pytest.approx(1.0 / env.task.skill.target_survival)
    row = learner.end_iteration()
    assert row["alone_progress"] is not None
    # The force statistics saw the helped rows only: the mean applied norm is the full help.
    helped_norm = float(torch.linalg.vector_norm(eta0[0] * math.tanh(1.0)))
    assert row["mean_applied_norm"][0] == pytest.approx(helped_norm, rel=1e-5)
    state = env.state_dict()
    other = quiet_env(num_envs=8, task=variant(episode_length_s=0.06))
    RecordingEnv(other, Algorithm1(AssistCurriculum(eta0, cfg)))
    other.load_state_dict(state)
    assert other.task_components.alone_skill.window.count == 2


def misplaced_tensors(env: G1VecEnv) -> list[str]:
    """Where a tensor of ``env.env_state``, the observations or a part's ``state_dict`` is not on
    ``env.device`` (the generator's saved state is a CPU byte tensor on every device: skipped)."""
    device = torch.device(env.device)
    found: list[str] = []

    def visit(where: str, value) -> None:
        if isinstance(value, torch.Tensor):
            same = value.device.type == device.type
            if same and device.index is not None:
                same = value.device.index == device.index
            if not same:
                found.append(f"{where} on {value.device}")
        elif isinstance(value, dict):
            for key, item in value.items():
                visit(f"{where}.{key}", item)
        elif isinstance(value, list | tuple):
            for i, item in enumerate(value):
                visit(f"{where}[{i}]", item)
        elif hasattr(value, "items") and hasattr(value, "batch_size"):  # TensorDict
            visit(where, value.to_dict())

    visit("env_state", vars(env.env_state))
    visit("observations", env.get_observations())
    state = env.state_dict()
    assert "generator" in state
    visit("state_dict", {k: v for k, v in state.items() if k != "generator"})
    return found


@pytest.mark.parametrize("task", ["stand", "walk", "backflip"])
def test_every_tensor_of_the_env_lives_on_its_device(task: str):
    """The parts build their tensors on ``env.device`` (MuJoCo C: the CPU; the Warp backend's
    device in ``test_warp_physics``), and the generator draws there."""
    env = make_env(task, 4, num_threads=1)
    try:
        gen = torch.Generator().manual_seed(0)
        for _ in range(3):
            env.step(torch.randn(4, env.num_actions, generator=gen))
        assert env.device == "cpu" and env.generator.device == torch.device("cpu")
        assert misplaced_tensors(env) == []
    finally:
        env.close()
