"""DreamWaQ-style history encoder: a beta-VAE over the observation history.

The encoder reads the last ``H`` (normalised) policy observations ``o^H_t`` and outputs a latent
``z_t`` (mean and log-variance) and an estimate ``v_hat_t`` of the base linear velocity [m/s, base
frame]. A decoder maps ``(z_t, v_hat_t)`` to the next observation ``o_{t+1}``. It is trained with
its own loss, next to PPO: reconstruction MSE of ``o_{t+1}`` + velocity MSE + ``beta`` times the KL
divergence to ``N(0, I)`` (paper Sec. III-C; Nahrendra et al., DreamWaQ, 2023).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from rsl_rl.modules import MLP
from torch import nn

LOG_VAR_RANGE: tuple[float, float] = (-10.0, 5.0)
"""Clamp of the latent log-variance, for a finite KL and reparameterisation."""


@dataclass
class EncoderOutput:
    """What the encoder infers from one history (each tensor has a leading batch shape)."""

    latent_mean: torch.Tensor  # (..., latent_dim) mean of q(z | o^H)
    latent_log_var: torch.Tensor  # (..., latent_dim) log-variance of q(z | o^H)
    base_lin_vel_b: torch.Tensor  # (..., 3) estimated base linear velocity [m/s], base frame


class HistoryEncoder(nn.Module):
    """Beta-VAE over ``o^H`` predicting ``o_{t+1}`` and the base velocity.

    Args:
        obs_dim: ``P``, size of one policy observation.
        history_length: ``H``, number of stacked observations in the input.
        latent_dim: size of ``z``.
        hidden_dims: hidden layers of the encoder (the decoder uses them reversed).
        activation: activation name understood by rsl_rl's :class:`~rsl_rl.modules.MLP`.
    """

    def __init__(
        self,
        obs_dim: int,
        history_length: int,
        latent_dim: int,
        hidden_dims: tuple[int, ...],
        activation: str = "elu",
    ) -> None:
        """Build encoder and decoder MLPs."""
        super().__init__()
        if obs_dim <= 0 or history_length <= 0 or latent_dim <= 0:
            raise ValueError(
                f"history encoder needs positive sizes, got obs_dim={obs_dim}, "
                f"history_length={history_length}, latent_dim={latent_dim}"
            )
        self.obs_dim = obs_dim
        self.history_length = history_length
        self.latent_dim = latent_dim
        self.encoder = MLP(
            obs_dim * history_length, 2 * latent_dim + 3, list(hidden_dims), activation
        )
        self.decoder = MLP(latent_dim + 3, obs_dim, list(reversed(hidden_dims)), activation)

    @property
    def output_dim(self) -> int:
        """Size of the features handed to the policy heads: ``z`` then ``v_hat``."""
        return self.latent_dim + 3

    def forward(self, history: torch.Tensor) -> EncoderOutput:
        """Encode a (normalised) history of shape (..., H * P)."""
        out = self.encoder(history)
        mean, log_var, vel = torch.split(out, [self.latent_dim, self.latent_dim, 3], dim=-1)
        return EncoderOutput(mean, log_var.clamp(*LOG_VAR_RANGE), vel)

    def policy_features(self, history: torch.Tensor) -> torch.Tensor:
        """Deterministic features for the policy heads: ``[z mean, v_hat]``, shape (..., Z + 3)."""
        enc = self.forward(history)
        return torch.cat([enc.latent_mean, enc.base_lin_vel_b], dim=-1)

    def loss(
        self,
        history: torch.Tensor,
        next_obs: torch.Tensor,
        base_lin_vel_b: torch.Tensor,
        kl_weight: float,
        velocity_weight: float = 1.0,
    ) -> dict[str, torch.Tensor]:
        """VAE losses on a batch.

        Args:
            history: (B, H * P) normalised history ``o^H_t``.
            next_obs: (B, P) normalised noise-free next observation ``o_{t+1}`` (target).
            base_lin_vel_b: (B, 3) true base linear velocity [m/s] (target).
            kl_weight: ``beta`` of the beta-VAE.
            velocity_weight: weight of the velocity MSE.

        Returns:
            ``total`` (to minimise) and its parts ``reconstruction``, ``velocity``, ``kl``.
        """
        enc = self.forward(history)
        std = torch.exp(0.5 * enc.latent_log_var)
        z = enc.latent_mean + std * torch.randn_like(std)
        prediction = self.decoder(torch.cat([z, enc.base_lin_vel_b], dim=-1))
        reconstruction = (prediction - next_obs).pow(2).mean()
        velocity = (enc.base_lin_vel_b - base_lin_vel_b).pow(2).mean()
        kl = -0.5 * torch.mean(
            torch.sum(
                1.0 + enc.latent_log_var - enc.latent_mean.pow(2) - enc.latent_log_var.exp(), -1
            )
        )
        total = reconstruction + velocity_weight * velocity + kl_weight * kl
        return {"total": total, "reconstruction": reconstruction, "velocity": velocity, "kl": kl}
