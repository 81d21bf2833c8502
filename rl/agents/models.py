"""The joint-action actor: a motion head and an assist head over a shared history latent.

One rsl-rl model (a :class:`~rsl_rl.models.MLPModel` subclass, so rsl-rl's PPO, storage and
Gaussian distribution are used unchanged) outputs the joint action
``a = [a_motion (29), a_assist (6)]`` (paper Sec. III-A, "joint action learner"):

- motion head input: ``[o_t, z_t, v_hat_t]`` (normalised observation, VAE latent mean, velocity
  estimate),
- assist head input: the same plus the normalised privileged observation (mode ``a2cf``), or the
  same without it (ablation ``no-pi``); no assist head at all in mode ``baseline``.

The history encoder (:class:`~rl.agents.vae.HistoryEncoder`) is shared by both heads; its features
are detached from the PPO graph, it learns from its own VAE loss (:class:`~rl.agents.ppo.A2CFPPO`).
The critic is rsl-rl's plain :class:`~rsl_rl.models.MLPModel` on the full-state group ("critic").
"""

from __future__ import annotations

import copy
import math

import torch
from rsl_rl.models import MLPModel
from rsl_rl.modules import MLP, EmpiricalNormalization
from rsl_rl.utils import resolve_class
from tensordict import TensorDict
from torch import nn
from torch.distributions import Normal

from rl.agents.vae import HistoryEncoder

ASSIST_ACTION_DIM = 6
"""Raw assist-head outputs: force x, y, z then moment x, y, z (squashed and bounded by the env)."""

ASSIST_OUTPUT_INIT_SCALE = 0.01
"""Scale of the assist head's last-layer initial weights (near-zero initial mean wrench)."""


class JointActionHeads(nn.Module):
    """Motion MLP on the first ``motion_input_dim`` features, assist MLP on the first
    ``assist_input_dim`` ones; outputs ``[motion, assist]`` concatenated.

    The input is ``[o_t, z_t, v_hat_t, privileged]``, so the privileged block is simply cut off for
    the motion head (and for the assist head in the ``no-pi`` ablation).
    """

    def __init__(
        self,
        motion_input_dim: int,
        num_motion_actions: int,
        motion_hidden_dims: tuple[int, ...],
        assist_input_dim: int | None,
        assist_hidden_dims: tuple[int, ...],
        activation: str,
    ) -> None:
        """Build the motion head and, when ``assist_input_dim`` is given, the assist head."""
        super().__init__()
        self.motion_input_dim = motion_input_dim
        self.assist_input_dim = assist_input_dim
        self.motion = MLP(
            motion_input_dim, num_motion_actions, list(motion_hidden_dims), activation
        )
        self.assist = (
            MLP(assist_input_dim, ASSIST_ACTION_DIM, list(assist_hidden_dims), activation)
            if assist_input_dim is not None
            else None
        )
        if self.assist is not None:
            # The assist agent starts neutral: mean wrench ~0 in every state, so the early wrench
            # is exploration noise (its std) rather than an arbitrary state-dependent push.
            last = self.assist[-1]
            with torch.no_grad():
                last.weight.mul_(ASSIST_OUTPUT_INIT_SCALE)
                last.bias.zero_()

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """(..., F) features -> (..., 29) or (..., 35) head outputs."""
        motion = self.motion(features[..., : self.motion_input_dim])
        if self.assist is None:
            return motion
        return torch.cat([motion, self.assist(features[..., : self.assist_input_dim])], dim=-1)


class A2CFActor(MLPModel):
    """Actor of the joint action learner (see module docstring).

    Constructed by rsl-rl's ``PPO.construct_algorithm`` from the runner config
    ``actor = {"class_name": "rl.agents.models:A2CFActor", ...}`` with
    ``obs_groups["actor"] = [policy_group, history_group(, privileged_group)]``.

    Args:
        obs: an observation TensorDict from the env (for sizes).
        obs_groups: rsl-rl observation sets.
        obs_set: the set of this model ("actor").
        output_dim: ``num_motion_actions`` (no assist head) or ``num_motion_actions + 6``.
        latent_dim: VAE latent size.
        encoder_hidden_dims: history-encoder hidden layers.
        motion_hidden_dims: motion-head hidden layers.
        assist_hidden_dims: assist-head hidden layers (sizes: no defaults here, they live once in
            :class:`rl.training.config.ModelConfig`).
        num_motion_actions: joint actions (29 for the G1).
        activation: activation name.
        obs_normalization: empirical normalisation of the policy and privileged observations.
        assist_privileged: the assist head reads the privileged group (False: ablation ``no-pi``).
        distribution_cfg: rsl-rl distribution config (Gaussian over the whole joint action).
        assist_init_std: initial std of the 6 assist dimensions (None: the distribution's
            ``init_std`` for all). The applied wrench is ``eta * tanh(raw)``: a small std makes the
            early wrench small, and Algorithm 1 then shrinks the bound before the head learns.
        kl_motion_only: the KL that sets rsl-rl's adaptive learning rate is the motion actions'
            only (False: over the joint action, rsl-rl's): a sharp warm-started assist head
            would otherwise hold the learning rate down (docs/training.md, item 9).
        assist_in_ratio_unhelped: the assist actions stay in PPO's log-probability (its ratio)
            and entropy once assistance is off for good (:attr:`helping` False), rsl-rl's joint
            action. False: only the motion actions count then; the 6 assist actions no longer
            move the env, so their terms are noise in every ratio, and the entropy bonus would
            widen their std without end.
        policy_group / history_group / privileged_group: names of the env's observation groups.
    """

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        *,
        latent_dim: int,
        encoder_hidden_dims: tuple[int, ...],
        motion_hidden_dims: tuple[int, ...],
        assist_hidden_dims: tuple[int, ...],
        num_motion_actions: int = 29,
        activation: str = "elu",
        obs_normalization: bool = True,
        assist_privileged: bool = True,
        distribution_cfg: dict | None = None,
        assist_init_std: float | None = None,
        kl_motion_only: bool = False,
        assist_in_ratio_unhelped: bool = True,
        policy_group: str = "policy",
        history_group: str = "history",
        privileged_group: str = "privileged",
    ) -> None:
        """Build encoder, heads, normalisers and the output distribution."""
        # MLPModel.__init__ builds one MLP over all groups; this model wires its own modules and
        # reuses MLPModel's forward, distribution and log-prob/entropy/KL plumbing.
        nn.Module.__init__(self)
        has_assist = output_dim == num_motion_actions + ASSIST_ACTION_DIM
        if not has_assist and output_dim != num_motion_actions:
            raise ValueError(
                f"actor output_dim must be {num_motion_actions} (motion only) or "
                f"{num_motion_actions + ASSIST_ACTION_DIM} (motion + assist), got {output_dim}"
            )
        expected = [policy_group, history_group]
        if has_assist and assist_privileged:
            expected.append(privileged_group)
        if list(obs_groups[obs_set]) != expected:
            raise ValueError(
                f"obs_groups['{obs_set}'] must be {expected} for this actor, got {obs_groups[obs_set]}"
            )
        for group in expected:
            if obs[group].ndim != 2:
                raise ValueError(
                    f"observation group '{group}' must be (num_envs, dim), got {obs[group].shape}"
                )
        obs_dim = int(obs[policy_group].shape[-1])
        history_dim = int(obs[history_group].shape[-1])
        if history_dim % obs_dim != 0:
            raise ValueError(
                f"history group '{history_group}' has {history_dim} entries, not a multiple of the "
                f"policy observation size {obs_dim}"
            )
        self.obs_groups = expected
        self.obs_dim = (
            obs_dim
            + history_dim
            + (int(obs[privileged_group].shape[-1]) if len(expected) == 3 else 0)
        )
        self.policy_group, self.history_group, self.privileged_group = (
            policy_group,
            history_group,
            privileged_group,
        )
        self.num_motion_actions = num_motion_actions
        self.has_assist = has_assist
        self.kl_motion_only = kl_motion_only
        self.assist_in_ratio_unhelped = assist_in_ratio_unhelped
        self.helping = True  # assistance on: the runner sets it from the curriculum
        self.assist_privileged = has_assist and assist_privileged
        self.history_length = history_dim // obs_dim
        self.policy_obs_dim = obs_dim

        self.obs_normalization = obs_normalization
        self.obs_normalizer = (
            EmpiricalNormalization(obs_dim) if obs_normalization else nn.Identity()
        )
        privileged_dim = int(obs[privileged_group].shape[-1]) if self.assist_privileged else 0
        self.privileged_normalizer = (
            EmpiricalNormalization(privileged_dim)
            if obs_normalization and self.assist_privileged
            else nn.Identity()
        )

        self.encoder = HistoryEncoder(
            obs_dim, self.history_length, latent_dim, encoder_hidden_dims, activation
        )
        motion_input_dim = obs_dim + self.encoder.output_dim
        assist_input_dim = (motion_input_dim + privileged_dim) if has_assist else None

        if distribution_cfg is not None:
            dist_class, dist_cfg = resolve_class(distribution_cfg)
            self.distribution = dist_class(output_dim, **dist_cfg)
            if self.distribution.input_dim != output_dim:
                raise ValueError(
                    "A2CFActor supports distributions with input_dim == output_dim (Gaussian)"
                )
        else:
            self.distribution = None
        self.mlp = JointActionHeads(
            motion_input_dim,
            num_motion_actions,
            motion_hidden_dims,
            assist_input_dim,
            assist_hidden_dims,
            activation,
        )
        if self.distribution is not None:
            self.distribution.init_mlp_weights(self.mlp)
        if has_assist and assist_init_std is not None:
            self._set_assist_std(assist_init_std)

    def _set_assist_std(self, std: float) -> None:
        """Initial std of the assist dimensions of a state-independent Gaussian."""
        if std <= 0:
            raise ValueError(f"assist_init_std must be > 0, got {std}")
        with torch.no_grad():
            if hasattr(self.distribution, "std_param"):
                self.distribution.std_param[self.num_motion_actions :] = std
            elif hasattr(self.distribution, "log_std_param"):
                self.distribution.log_std_param[self.num_motion_actions :] = math.log(std)
            else:
                raise ValueError(
                    "assist_init_std needs rsl-rl's GaussianDistribution (state-independent std)"
                )

    def get_kl_divergence(
        self, old_params: tuple[torch.Tensor, ...], new_params: tuple[torch.Tensor, ...]
    ) -> torch.Tensor:
        """KL(old || new) per sample, summed over the motion actions only where
        ``kl_motion_only`` (the assist head's moves then do not slow the motion policy's
        learning rate), else over the joint action."""
        if self.kl_motion_only and self.has_assist:
            n = self.num_motion_actions
            old_params = tuple(p[..., :n] for p in old_params)
            new_params = tuple(p[..., :n] for p in new_params)
        return super().get_kl_divergence(old_params, new_params)

    def _motion_only(self) -> bool:
        return self.has_assist and not self.helping and not self.assist_in_ratio_unhelped

    def _motion_distribution(self) -> Normal:
        mean, std = self.distribution.params
        n = self.num_motion_actions
        return Normal(mean[..., :n], std[..., :n])

    @property
    def output_entropy(self) -> torch.Tensor:
        """Entropy of the action distribution (of the motion actions only where
        :meth:`_motion_only`)."""
        if self._motion_only():
            return self._motion_distribution().entropy().sum(dim=-1)
        return super().output_entropy

    def get_output_log_prob(self, outputs: torch.Tensor) -> torch.Tensor:
        """Log-probability of actions (of their motion part only where :meth:`_motion_only`:
        set before a rollout, so a rollout and its update count the same actions)."""
        if self._motion_only():
            n = self.num_motion_actions
            return self._motion_distribution().log_prob(outputs[..., :n]).sum(dim=-1)
        return super().get_output_log_prob(outputs)

    def normalized_history(self, history: torch.Tensor) -> torch.Tensor:
        """Normalise each of the ``H`` stacked observations, shape kept (..., H * P)."""
        frames = history.reshape(*history.shape[:-1], self.history_length, self.policy_obs_dim)
        return self.obs_normalizer(frames).reshape(history.shape)

    def get_latent(
        self, obs: TensorDict, masks: torch.Tensor | None = None, hidden_state: None = None
    ) -> torch.Tensor:
        """Features ``[o_t, z_t, v_hat_t(, privileged)]`` fed to :class:`JointActionHeads`."""
        policy = self.obs_normalizer(obs[self.policy_group])
        with torch.no_grad():  # the encoder learns from its own loss only
            encoded = self.encoder.policy_features(self.normalized_history(obs[self.history_group]))
        parts = [policy, encoded]
        if self.assist_privileged:
            parts.append(self.privileged_normalizer(obs[self.privileged_group]))
        return torch.cat(parts, dim=-1)

    def update_normalization(self, obs: TensorDict) -> None:
        """Update the running statistics from a (flattened) batch of observations."""
        if self.obs_normalization:
            self.obs_normalizer.update(obs[self.policy_group])  # type: ignore[operator]
            if self.assist_privileged:
                self.privileged_normalizer.update(obs[self.privileged_group])  # type: ignore[operator]

    def policy_parameters(self) -> list[nn.Parameter]:
        """Parameters trained by PPO (everything but the history encoder)."""
        encoder_ids = {id(p) for p in self.encoder.parameters()}
        return [p for p in self.parameters() if id(p) not in encoder_ids]

    def motion_policy(self) -> MotionPolicy:
        """The deployable motion policy alone (normaliser, encoder, motion head), deterministic."""
        return MotionPolicy(self)

    def as_jit(self) -> nn.Module:
        """TorchScript-ready motion policy (no assist head)."""
        return self.motion_policy()

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        """ONNX-ready motion policy (no assist head); see :mod:`rl.agents.export`."""
        return self.motion_policy()


class MotionPolicy(nn.Module):
    """Deployment policy: ``(obs (B, P), history (B, H * P)) -> motion action (B, 29)``.

    A copy of the actor's normaliser, encoder and motion head; the action mean is returned (the
    joint target is ``STAND_JOINT_POS_RAD + ACTION_SCALE_RAD * action``).
    """

    input_names = ["obs", "history"]
    output_names = ["actions"]

    def __init__(self, actor: A2CFActor) -> None:
        """Copy the deploy-time parts of ``actor`` (later training does not change this copy)."""
        super().__init__()
        self.obs_normalizer = copy.deepcopy(actor.obs_normalizer)
        self.encoder = copy.deepcopy(actor.encoder)
        self.motion = copy.deepcopy(actor.mlp.motion)
        self.history_length = actor.history_length
        self.policy_obs_dim = actor.policy_obs_dim

    def forward(self, obs: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        """Deterministic motion action for a batch."""
        frames = history.reshape(history.shape[0], self.history_length, self.policy_obs_dim)
        history_n = self.obs_normalizer(frames).reshape(history.shape[0], -1)
        features = self.encoder.policy_features(history_n)
        return self.motion(torch.cat([self.obs_normalizer(obs), features], dim=-1))

    def get_dummy_inputs(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Zero inputs of the right sizes (batch 1) for tracing."""
        return (
            torch.zeros(1, self.policy_obs_dim),
            torch.zeros(1, self.history_length * self.policy_obs_dim),
        )
