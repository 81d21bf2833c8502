"""The joint-action actor, the VAE history encoder, the PPO extension and the ONNX export."""

from __future__ import annotations

import pytest
import torch
from rsl_rl.models import MLPModel
from rsl_rl.storage import RolloutStorage
from tensordict import TensorDict

from rl.a2cf.config import MODES, get_mode
from rl.agents.export import OnnxMotionPolicy, export_motion_policy
from rl.agents.models import A2CFActor
from rl.agents.ppo import A2CFPPO
from rl.agents.vae import HistoryEncoder

N, P, H, K, C = 8, 12, 3, 7, 25  # tiny sizes: envs, obs, history, privileged, critic
GAUSSIAN = {"class_name": "GaussianDistribution", "init_std": 1.0}


def make_obs(n: int = N, seed: int = 0) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    return TensorDict(
        {
            "policy": torch.randn(n, P, generator=g),
            "history": torch.randn(n, H * P, generator=g),
            "privileged": torch.randn(n, K, generator=g),
            "critic": torch.randn(n, C, generator=g),
            "base_lin_vel": torch.randn(n, 3, generator=g),
            "policy_clean": torch.randn(n, P, generator=g),
        },
        batch_size=[n],
    )


SIZES = dict(
    latent_dim=4, encoder_hidden_dims=(16,), motion_hidden_dims=(16,), assist_hidden_dims=(16,)
)


def make_actor(output_dim: int = 35, privileged: bool = True) -> A2CFActor:
    groups = ["policy", "history"] + (["privileged"] if privileged and output_dim == 35 else [])
    return A2CFActor(
        make_obs(),
        {"actor": groups},
        "actor",
        output_dim,
        **SIZES,
        assist_privileged=privileged,
        distribution_cfg=GAUSSIAN,
    )


def test_modes_table() -> None:
    assert set(MODES) == {"baseline", "a2cf", "no-pi", "no-id", "no-rm", "coach"}
    assert not get_mode("baseline").assist
    assert get_mode("a2cf").assist_privileged and get_mode("a2cf").random_mask
    assert not get_mode("no-pi").assist_privileged
    assert get_mode("no-id").identical_initial_bounds
    assert not get_mode("no-rm").random_mask
    with pytest.raises(ValueError, match="unknown training mode"):
        get_mode("a3cf")


def test_actor_joint_action_shapes_and_distribution() -> None:
    actor = make_actor()
    obs = make_obs()
    actions = actor(obs, stochastic_output=True)
    assert actions.shape == (N, 35)
    assert actor.get_output_log_prob(actions).shape == (N,)
    assert actor.output_std.shape == (N, 35)
    assert make_actor(output_dim=29)(obs).shape == (N, 29)


def test_motion_head_ignores_privileged_info_assist_head_uses_it() -> None:
    actor = make_actor()
    obs, changed = make_obs(), make_obs()
    changed["privileged"] = changed["privileged"] + 5.0
    a, b = actor(obs), actor(changed)
    torch.testing.assert_close(a[:, :29], b[:, :29])
    assert (a[:, 29:] - b[:, 29:]).abs().max() > 1e-4
    # no-pi: the assist head cannot see it either
    no_pi = make_actor(privileged=False)
    torch.testing.assert_close(no_pi(obs), no_pi(changed))


def test_both_heads_read_the_history_latent() -> None:
    actor = make_actor()
    obs, changed = make_obs(), make_obs()
    changed["history"] = changed["history"] + 1.0
    a, b = actor(obs), actor(changed)
    assert (a[:, :29] - b[:, :29]).abs().max() > 1e-4
    assert (a[:, 29:] - b[:, 29:]).abs().max() > 1e-4


def test_actor_rejects_wrong_groups_and_sizes() -> None:
    with pytest.raises(ValueError, match="obs_groups"):
        A2CFActor(make_obs(), {"actor": ["policy"]}, "actor", 35, **SIZES)
    with pytest.raises(ValueError, match="output_dim"):
        A2CFActor(make_obs(), {"actor": ["policy", "history"]}, "actor", 30, **SIZES)


def test_ppo_gradients_do_not_reach_the_encoder() -> None:
    actor = make_actor()
    actor(make_obs(), stochastic_output=True)
    loss = actor.get_output_log_prob(torch.zeros(N, 35)).mean()
    loss.backward()
    assert all(p.grad is None for p in actor.encoder.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in actor.mlp.parameters())


def test_vae_learns_velocity_and_next_observation() -> None:
    torch.manual_seed(0)
    enc = HistoryEncoder(P, H, latent_dim=4, hidden_dims=(64, 32))
    opt = torch.optim.Adam(enc.parameters(), lr=3e-3)
    w_vel, w_next = torch.randn(H * P, 3) / (H * P) ** 0.5, torch.randn(H * P, P) / (H * P) ** 0.5
    history = torch.randn(512, H * P)
    vel, nxt = history @ w_vel, history @ w_next
    first = {k: float(v.detach()) for k, v in enc.loss(history, nxt, vel, kl_weight=1e-3).items()}
    for _ in range(300):
        parts = enc.loss(history, nxt, vel, kl_weight=1e-3)
        opt.zero_grad()
        parts["total"].backward()
        opt.step()
    assert float(parts["velocity"].detach()) < 0.2 * first["velocity"]
    assert float(parts["reconstruction"].detach()) < 0.5 * first["reconstruction"]


def fill_storage(alg: A2CFPPO, steps: int) -> None:
    obs = make_obs()
    for t in range(steps):
        alg.act(obs)
        obs = make_obs(seed=t + 1)
        dones = torch.zeros(N, dtype=torch.long)
        dones[0] = int(t == 1)
        alg.process_env_step(
            obs, torch.randn(N), dones, {"time_outs": torch.zeros(N, dtype=torch.bool)}
        )
    alg.compute_returns(obs)


def test_a2cf_ppo_update_trains_policy_critic_and_encoder_separately() -> None:
    actor = make_actor()
    critic = MLPModel(make_obs(), {"critic": ["critic"]}, "critic", 1, hidden_dims=(16,))
    steps = 4
    storage = RolloutStorage("rl", N, steps, make_obs(), [35])
    alg = A2CFPPO(actor, critic, storage, num_learning_epochs=2, num_mini_batches=2)
    ppo_params = {id(p) for group in alg.optimizer.param_groups for p in group["params"]}
    assert not ppo_params & {id(p) for p in actor.encoder.parameters()}
    assert {id(p) for p in critic.parameters()} <= ppo_params
    assert {id(p) for p in actor.mlp.parameters()} <= ppo_params

    fill_storage(alg, steps)
    history, next_clean, velocity = alg._encoder_dataset()
    assert history.shape == (steps * N - 1, H * P)  # env 0 ended its episode at t = 1
    before_enc = [p.clone() for p in actor.encoder.parameters()]
    before_head = [p.clone() for p in actor.mlp.parameters()]
    losses = alg.update()
    assert {"surrogate", "value", "entropy", "vae_reconstruction", "vae_velocity", "vae_kl"} <= set(
        losses
    )
    assert all(torch.isfinite(torch.tensor(v)) for v in losses.values())
    assert any((a != b).any() for a, b in zip(before_enc, actor.encoder.parameters(), strict=True))
    assert any((a != b).any() for a, b in zip(before_head, actor.mlp.parameters(), strict=True))
    state = alg.save()
    assert "vae_optimizer_state_dict" in state
    alg.load(state, None, strict=True)


def test_onnx_export_matches_torch(tmp_path) -> None:
    actor = make_actor()
    actor.update_normalization(make_obs(64, seed=3))  # non-trivial normaliser statistics
    info = export_motion_policy(actor, tmp_path / "policy.onnx")
    assert info["max_abs_error"] < 1e-5 and info["outputs"]["actions"] == [29]
    obs = make_obs(5, seed=9)
    onnx_actions = OnnxMotionPolicy(tmp_path / "policy.onnx")(
        obs["policy"].numpy(), obs["history"].numpy()
    )
    torch.testing.assert_close(
        torch.from_numpy(onnx_actions), actor(obs)[:, :29].detach(), atol=1e-5, rtol=1e-5
    )
    assert (tmp_path / "policy.json").is_file()


def test_assist_dimensions_get_their_own_initial_std() -> None:
    actor = A2CFActor(
        make_obs(),
        {"actor": ["policy", "history", "privileged"]},
        "actor",
        35,
        **SIZES,
        distribution_cfg={"class_name": "GaussianDistribution", "init_std": 0.5},
        assist_init_std=1.5,
    )
    actor(make_obs(), stochastic_output=True)
    std = actor.output_std[0]
    torch.testing.assert_close(std[:29], torch.full((29,), 0.5))
    torch.testing.assert_close(std[29:], torch.full((6,), 1.5))


def test_assist_head_starts_neutral() -> None:
    actor = make_actor()
    mean = actor(make_obs(64, seed=5))
    assert mean[:, 29:].abs().max() < 0.05  # tanh(raw) ~ 0: no systematic push before learning
    assert mean[:, :29].abs().max() > 0.05  # the motion head keeps rsl-rl's default init


@pytest.mark.parametrize(("vae_epochs", "passes"), [(0, 3), (1, 1)])
def test_encoder_update_makes_its_own_number_of_passes(vae_epochs: int, passes: int) -> None:
    """0 follows PPO's epochs (the default, as before); k > 0 makes k passes of 2 mini-batches."""
    actor = make_actor()
    critic = MLPModel(make_obs(), {"critic": ["critic"]}, "critic", 1, hidden_dims=(16,))
    storage = RolloutStorage("rl", N, 4, make_obs(), [35])
    alg = A2CFPPO(
        actor, critic, storage, num_learning_epochs=3, num_mini_batches=2,
        vae_learning_epochs=vae_epochs,
    )  # fmt: skip
    fill_storage(alg, 4)
    steps = []
    alg.vae_optimizer.register_step_post_hook(lambda *_: steps.append(1))
    alg.update()
    assert len(steps) == 2 * passes


def test_negative_encoder_epochs_are_refused() -> None:
    storage = RolloutStorage("rl", N, 4, make_obs(), [35])
    critic = MLPModel(make_obs(), {"critic": ["critic"]}, "critic", 1, hidden_dims=(16,))
    with pytest.raises(ValueError, match="vae_learning_epochs"):
        A2CFPPO(make_actor(), critic, storage, vae_learning_epochs=-1)


def test_the_adaptive_learning_rate_can_follow_the_motion_actions_kl_alone() -> None:
    joint = make_actor()
    obs = make_obs(16, seed=3)
    joint(obs, stochastic_output=True)
    old = tuple(p.detach().clone() for p in joint.output_distribution_params)
    moved_assist = (old[0].clone(), old[1].clone())
    moved_assist[0][:, 29:] += 1.0  # only the assist head's mean moves
    assert float(joint.get_kl_divergence(old, moved_assist).min()) > 1.0  # rsl-rl's: all 35
    motion = make_actor()
    motion.kl_motion_only = True
    torch.testing.assert_close(motion.get_kl_divergence(old, moved_assist), torch.zeros(16))
    moved_motion = (old[0] + 0.1, old[1])
    assert float(motion.get_kl_divergence(old, moved_motion).min()) > 0.0


def test_kl_actions_is_checked() -> None:
    from rl.training.config import PPOConfig, TrainConfig

    with pytest.raises(ValueError, match="--ppo-kl-actions"):
        TrainConfig(ppo=PPOConfig(kl_actions="assist"))


@pytest.mark.parametrize("in_ratio", [True, False])
def test_the_assist_actions_leave_ppos_ratio_once_help_is_off(in_ratio: bool) -> None:
    """Once assistance is off for good, the assist actions move nothing: with
    ``assist_in_ratio_unhelped`` False they leave the log-probability and the entropy, so PPO's
    update no longer touches the assist head or its std; rsl-rl's joint action keeps both."""
    torch.manual_seed(0)
    actor = make_actor()
    actor.assist_in_ratio_unhelped = in_ratio
    obs = make_obs()
    actions = actor(obs, stochastic_output=True)
    full = actor.get_output_log_prob(actions)
    mean, std = (p.detach() for p in actor.output_distribution_params)
    motion = torch.distributions.Normal(mean[:, :29], std[:, :29])
    actor.helping = False
    expected = motion.log_prob(actions[:, :29]).sum(-1) if not in_ratio else full
    torch.testing.assert_close(actor.get_output_log_prob(actions), expected)
    entropy = motion.entropy().sum(-1) if not in_ratio else actor.distribution.entropy
    torch.testing.assert_close(actor.output_entropy, entropy)
    actor.helping = True  # while it helps, the joint action in either case
    torch.testing.assert_close(actor.get_output_log_prob(actions), full)

    critic = MLPModel(make_obs(), {"critic": ["critic"]}, "critic", 1, hidden_dims=(16,))
    storage = RolloutStorage("rl", N, 4, make_obs(), [35])
    alg = A2CFPPO(actor, critic, storage, num_learning_epochs=2, num_mini_batches=2)
    alg.set_helping(False)
    fill_storage(alg, 4)
    assist = [p.clone() for p in actor.mlp.assist.parameters()]
    std_before = actor.distribution.std_param.detach().clone()
    alg.update()
    moved = [
        bool((a != b).any()) for a, b in zip(assist, actor.mlp.assist.parameters(), strict=True)
    ]
    std_after = actor.distribution.std_param.detach()
    assert any(moved) == in_ratio
    assert bool((std_after[29:] != std_before[29:]).any()) == in_ratio
    assert (std_after[:29] != std_before[:29]).any()  # the motion actions keep learning


def test_assist_in_ratio_is_checked() -> None:
    from rl.training.config import PPOConfig, TrainConfig

    with pytest.raises(ValueError, match="--ppo-assist-in-ratio"):
        TrainConfig(ppo=PPOConfig(assist_in_ratio="never"))
