"""Applying the assist head's output: squash into the bound, random mask, pelvis ``xfrc_applied``.

The contract (``docs/environments.md``, "Actions and the assist wrench"): actions[:, 29:35] are
the assist head's raw, unbounded output; the applied pelvis wrench is
F = mask * eta[phase] * tanh(raw), force [N] then torque [Nm] at the pelvis centre of mass in the
robot's heading frame (the env turns it into MuJoCo's world-frame ``xfrc_applied`` of the pelvis;
the frame is stated in :class:`rl.envs.assist_action.AssistAction`);
each mask component is 0 with probability zeta, resampled every control step; F = 0 when
assistance is disabled. The functions here are frame-free (per-axis squash and mask).
"""

from __future__ import annotations

import torch

from optimal_control.bounds import AXIS_NAMES, PAPER_ETA0

WRENCH_DIM = 6
"""Force (3) then torque (3)."""

DEFAULT_RANDOM_MASK_PROB = 0.2
"""zeta of the paper's random mask (RM): each wrench component dropped with probability 0.2."""


def squash_wrench(raw: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """Map raw head outputs (N, 6) into the hypercube |F_i| <= bound_i (N, 6): bound * tanh(raw)."""
    return bound * torch.tanh(raw)


def sample_mask(
    shape: tuple[int, ...], drop_prob: float, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Random mask of 0/1 floats, each entry 0 with probability ``drop_prob`` (zeta)."""
    if not 0.0 <= drop_prob <= 1.0:
        raise ValueError(f"Random mask probability zeta must be in [0, 1], got {drop_prob}.")
    device = generator.device if generator is not None else None  # draw where the stream lives
    return (torch.rand(shape, generator=generator, device=device) >= drop_prob).to(torch.float32)


def assist_wrench(raw: torch.Tensor, bound: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """The wrench (N, 6) to apply: mask * bound * tanh(raw)."""
    return mask * squash_wrench(raw, bound)


def raw_from_wrench(wrench: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """The raw head output whose squash gives ``wrench`` (atanh of the bound fraction, clipped
    to 0.995 of the bound): what a coach's wrench is as an assist action."""
    ratio = torch.where(bound > 0, wrench / bound.clamp_min(1e-9), 0.0).clamp(-0.995, 0.995)
    return torch.atanh(ratio)


class AssistState:
    """The assist settings the runner changes between iterations, and the wrench they produce.

    Holds eta (num_phases, 6) [N, Nm], whether assistance is on, zeta and the less-assist switch.
    """

    def __init__(
        self,
        bound: torch.Tensor,
        enabled: bool,
        mask_prob: float,
        less_assist_reward: bool,
        generator: torch.Generator | None = None,
    ) -> None:
        self.bound = torch.zeros_like(bound, dtype=torch.float32)
        self.set_bound(bound)
        self.enabled = bool(enabled)
        self.mask_prob = 0.0
        self.set_mask_prob(mask_prob)
        self.less_assist_reward = bool(less_assist_reward)
        self.generator = generator

    @property
    def num_phases(self) -> int:
        """Number of task phases, one bound row each."""
        return self.bound.shape[0]

    def set_bound(self, bound: torch.Tensor) -> None:
        """Replace eta; ``bound`` must be (num_phases, 6), finite and non-negative (it is moved to
        the device of the first bound)."""
        bound = torch.as_tensor(bound, dtype=torch.float32, device=self.bound.device)
        if bound.shape != self.bound.shape:
            raise ValueError(
                f"Assist bound eta must have shape {tuple(self.bound.shape)} (num_phases, 6), "
                f"got {tuple(bound.shape)}."
            )
        if not torch.isfinite(bound).all() or (bound < 0).any():
            raise ValueError(f"Assist bound eta must be finite and >= 0, got {bound.tolist()}.")
        self.bound = bound.clone()

    def set_mask_prob(self, mask_prob: float) -> None:
        """Set zeta, the probability of dropping each wrench component."""
        if not 0.0 <= float(mask_prob) <= 1.0:
            raise ValueError(f"Random mask probability zeta must be in [0, 1], got {mask_prob}.")
        self.mask_prob = float(mask_prob)

    def wrench(
        self, raw: torch.Tensor, phase: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Wrench (N, 6) for raw head outputs (N, 6) of envs in phases (N,).

        Returns (wrench, bound of each env's phase (N, 6), mask (N, 6)); all zero when disabled.
        """
        bound = self.bound[phase]
        mask = sample_mask(tuple(raw.shape), self.mask_prob, self.generator)
        if not self.enabled:
            return torch.zeros_like(raw), bound, mask
        return assist_wrench(raw, bound, mask), bound, mask


WRENCH_AXES: tuple[str, ...] = AXIS_NAMES
"""Names of the six wrench components: force [N] then moment [Nm] at the pelvis, on the axes of
the robot's heading frame (:class:`rl.envs.assist_action.AssistAction`)."""


def paper_bound_rows(paper_task: str) -> tuple[tuple[float, ...], ...]:
    """The paper's hand-set initial bounds of ``paper_task`` ("walk", "dance", "backflip"), one
    6-D row per phase, from the one table :data:`optimal_control.bounds.PAPER_ETA0`."""
    if paper_task not in PAPER_ETA0:
        raise ValueError(
            f"the paper has no initial-bound row for '{paper_task}'; known: {sorted(PAPER_ETA0)}"
        )
    return tuple(tuple(float(v) for v in row) for row in PAPER_ETA0[paper_task]["all"])


def less_assist(applied_wrench: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """A2CF less-assist reward exp(-2 |F| / |eta|) of the applied wrench (N, 6) and its bound (N, 6).

    1 without help; an env whose bound is zero (no help possible) gets 1. Added by the env (not a
    task term) while the curriculum has it switched on.
    """
    force_norm = applied_wrench.norm(dim=-1)
    bound_norm = bound.norm(dim=-1)
    ratio = torch.where(
        bound_norm > 0, force_norm / bound_norm.clamp_min(1e-9), torch.zeros_like(force_norm)
    )
    return torch.exp(-2.0 * ratio)
