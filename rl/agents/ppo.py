"""rsl-rl PPO over the joint action, extended with the history encoder's VAE update.

:class:`A2CFPPO` is rsl-rl's :class:`~rsl_rl.algorithms.PPO` unchanged for the policy/critic update
(clipped surrogate, clipped value loss, adaptive KL learning rate, GAE) with three additions:

- the PPO optimiser holds the actor's policy parameters and the critic, not the encoder;
- after each PPO update the encoder is trained on the same rollout with its own optimiser and the
  VAE loss (next-observation reconstruction, velocity MSE, KL), same epochs and mini-batches;
- the VAE optimiser state is saved and loaded with the rest.

Targets for the transition at step ``t``: ``history[t] -> policy_clean[t + 1]`` (the noise-free
next observation; the last step uses the observation handed to :meth:`compute_returns`) and
``base_lin_vel[t]``. Transitions that end an episode are skipped (their next observation belongs to
the next episode).
"""

from __future__ import annotations

from itertools import chain

import torch
from rsl_rl.algorithms import PPO
from rsl_rl.models import MLPModel
from rsl_rl.storage import RolloutStorage
from rsl_rl.utils import reduce_gradients_in_buckets, resolve_optimizer
from tensordict import TensorDict
from torch import nn

from rl.agents.models import A2CFActor


class A2CFPPO(PPO):
    """PPO on the joint action plus the VAE history-encoder update (see module docstring).

    Args (beyond rsl-rl's PPO):
        vae_learning_rate: Adam learning rate of the encoder.
        vae_kl_weight: ``beta`` of the beta-VAE loss.
        vae_velocity_weight: weight of the velocity-estimation MSE.
        vae_learning_epochs: passes of the encoder update over each rollout; 0 = PPO's
            ``num_learning_epochs`` (the encoder update costs about half the PPO update per pass).
        next_obs_group: observation group holding the noise-free ``o_t`` (target of ``t - 1``).
        velocity_group: observation group holding the true base linear velocity [m/s, base frame].
    """

    actor: A2CFActor

    def __init__(
        self,
        actor: A2CFActor,
        critic: MLPModel,
        storage: RolloutStorage,
        vae_learning_rate: float = 1e-3,
        vae_kl_weight: float = 1e-3,
        vae_velocity_weight: float = 1.0,
        vae_learning_epochs: int = 0,
        next_obs_group: str = "policy_clean",
        velocity_group: str = "base_lin_vel",
        optimizer: str = "adam",
        learning_rate: float = 1e-3,
        **kwargs,
    ) -> None:
        """Build rsl-rl's PPO, then split the encoder off into its own optimiser."""
        if not isinstance(actor, A2CFActor):
            raise TypeError(f"A2CFPPO needs an A2CFActor, got {type(actor).__name__}")
        super().__init__(
            actor, critic, storage, optimizer=optimizer, learning_rate=learning_rate, **kwargs
        )
        self.optimizer = resolve_optimizer(optimizer)(
            chain(self.actor.policy_parameters(), self.critic.parameters()), lr=learning_rate
        )  # type: ignore[call-arg]
        self.vae_optimizer = torch.optim.Adam(self.actor.encoder.parameters(), lr=vae_learning_rate)
        self.vae_kl_weight = vae_kl_weight
        self.vae_velocity_weight = vae_velocity_weight
        if vae_learning_epochs < 0:
            raise ValueError(
                f"vae_learning_epochs must be >= 0 (0: PPO's epochs), got {vae_learning_epochs}"
            )
        self.vae_learning_epochs = vae_learning_epochs or self.num_learning_epochs
        self.next_obs_group = next_obs_group
        self.velocity_group = velocity_group
        self._last_obs: TensorDict | None = None

    def compute_returns(self, obs: TensorDict) -> None:
        """GAE as in rsl-rl; keeps ``obs`` as the next observation of the rollout's last step."""
        self._last_obs = obs.clone()
        super().compute_returns(obs)

    def update(self) -> dict[str, float]:
        """rsl-rl's PPO update, then the VAE update on the same rollout; merged loss dict."""
        losses = super().update()  # clears only the write cursor; the rollout data stays
        losses.update(self.update_encoder())
        return losses

    def set_helping(self, helping: bool) -> None:
        """Whether assistance is on (the curriculum's): the actor counts the assist actions in
        PPO's ratio and entropy while it is, and after it only where it always does
        (``assist_in_ratio_unhelped``). At the switch off, Adam's first moments of the assist
        head and std are cleared: their gradients are zero from then on, and the moments of the
        helped updates would otherwise keep moving them for tens of steps."""
        actor = self.actor
        stopping = actor.helping and not helping
        actor.helping = helping
        if not (stopping and actor.has_assist and not actor.assist_in_ratio_unhelped):
            return
        n = actor.num_motion_actions
        std = getattr(actor.distribution, "std_param", None)
        if std is None:
            std = actor.distribution.log_std_param
        for param, rows in [(p, slice(None)) for p in actor.mlp.assist.parameters()] + [
            (std, slice(n, None))
        ]:
            moment = self.optimizer.state.get(param, {}).get("exp_avg")
            if moment is not None:
                moment[rows] = 0.0

    def _encoder_dataset(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(history (M, H*P), next clean obs (M, P), base velocity (M, 3)) of valid transitions."""
        if self._last_obs is None:
            raise RuntimeError("compute_returns(obs) must run before the encoder update")
        obs = self.storage.observations
        for group in (self.actor.history_group, self.next_obs_group, self.velocity_group):
            if group not in obs:
                raise KeyError(
                    f"the env's observations lack group '{group}' needed by the history encoder "
                    f"(have {list(obs.keys())})"
                )
        next_clean = torch.cat(
            [obs[self.next_obs_group][1:], self._last_obs[self.next_obs_group].unsqueeze(0)]
        )
        valid = self.storage.dones.squeeze(-1) == 0
        return (
            obs[self.actor.history_group][valid],
            next_clean[valid],
            obs[self.velocity_group][valid],
        )

    def update_encoder(self) -> dict[str, float]:
        """Train the history encoder on the stored rollout; mean VAE losses ``vae_*``."""
        history, next_clean, velocity = self._encoder_dataset()
        with torch.no_grad():
            history_n = self.actor.normalized_history(history)
            next_n = self.actor.obs_normalizer(next_clean)
        num_samples = history_n.shape[0]
        sums = {"vae_reconstruction": 0.0, "vae_velocity": 0.0, "vae_kl": 0.0}
        if num_samples == 0 and not self.is_multi_gpu:
            return sums
        # num_mini_batches steps per epoch on every rank (the ranks' sample counts differ: episode
        # ends are skipped), so that the ranks' gradient all-reduces pair up.
        batch_size = max(1, num_samples // self.num_mini_batches)
        encoder_params = list(self.actor.encoder.parameters())
        num_updates = 0
        for _ in range(self.vae_learning_epochs):
            order = torch.randperm(num_samples, device=history_n.device)
            for step in range(self.num_mini_batches):
                idx = order[step * batch_size : (step + 1) * batch_size]
                self.vae_optimizer.zero_grad()
                if idx.numel():
                    parts = self.actor.encoder.loss(
                        history_n[idx],
                        next_n[idx],
                        velocity[idx],
                        self.vae_kl_weight,
                        self.vae_velocity_weight,
                    )
                    parts["total"].backward()
                    for key in ("reconstruction", "velocity", "kl"):
                        sums[f"vae_{key}"] += float(parts[key].detach())
                    num_updates += 1
                if self.is_multi_gpu:
                    # As rsl-rl's reduce_parameters does for the policy: one encoder on all ranks.
                    for param in encoder_params:
                        if param.grad is None:
                            param.grad = torch.zeros_like(param)
                    reduce_gradients_in_buckets(
                        encoder_params, self.gpu_world_size, self.grad_reduce_bucket_mb
                    )
                elif not idx.numel():
                    continue
                nn.utils.clip_grad_norm_(encoder_params, self.max_grad_norm)
                self.vae_optimizer.step()
        # rsl-rl's PPO update clips the gradient norm over *all* actor parameters, the encoder's
        # included: stale VAE gradients left here would shrink the next PPO step (and a resumed
        # run, which starts without them, would diverge from the uninterrupted one).
        self.vae_optimizer.zero_grad(set_to_none=True)
        return {key: value / max(num_updates, 1) for key, value in sums.items()}

    def save(self) -> dict:
        """rsl-rl's saved dict plus the encoder optimiser."""
        saved = super().save()
        saved["vae_optimizer_state_dict"] = self.vae_optimizer.state_dict()
        return saved

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """rsl-rl's load plus the encoder optimiser (when optimisers are loaded)."""
        load_iteration = super().load(loaded_dict, load_cfg, strict)
        if (
            load_cfg is None or load_cfg.get("optimizer")
        ) and "vae_optimizer_state_dict" in loaded_dict:
            self.vae_optimizer.load_state_dict(loaded_dict["vae_optimizer_state_dict"])
        return load_iteration
