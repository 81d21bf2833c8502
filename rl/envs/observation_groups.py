"""The observation groups the env returns: the task's terms per group, their noise and the policy
history (the env's observation part)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import torch
from tensordict import TensorDict

from rl.envs.buffers import HistoryBuffer

if TYPE_CHECKING:
    from rl.envs.state import EnvState
    from rl.envs.task_schema import ObservationsConfig
    from rl.envs.terms import ObsGroup

TASK_GROUPS = ("policy", "privileged", "critic")
"""The groups a task defines; the env derives ``policy_clean``, ``history`` and ``base_lin_vel``."""


class ObservationGroups:
    """Builds the groups of ``docs/environments.md`` ("Observations") from an :class:`EnvState`:
    ``policy`` (noisy when the task says so), ``policy_clean``, ``history`` (the last H noisy policy
    rows, oldest first), ``privileged``, ``critic`` and ``base_lin_vel`` (the VAE's target,
    (N, 3) [m/s])."""

    def __init__(
        self,
        cfg: ObservationsConfig,
        num_envs: int,
        history_length: int,
        noise: bool,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> None:
        """``noise``: the env's switch (off: every group is clean). History, noise and the groups
        live on ``device`` (the generator's)."""
        self.cfg, self.num_envs, self.history_length = cfg, num_envs, history_length
        self.noise, self.generator, self.device = noise, generator, device
        self.history: HistoryBuffer | None = None  # sized by the first policy row
        self.obs: TensorDict | None = None
        self._noise_scale: dict[str, torch.Tensor] = {}

    def compute(self, s: EnvState, reset_ids: torch.Tensor, stepped: bool) -> TensorDict:
        """All groups of ``s``: after a step (``stepped``) the new policy row enters the history;
        the history of ``reset_ids`` (M,) is filled with their row."""
        cache: dict[int, torch.Tensor] = {}
        clean, noisy = self._group("policy", self.cfg.policy, s, cache)
        push = stepped or self.history is None
        if self.history is None:
            self.history = HistoryBuffer(
                self.num_envs, self.history_length, clean.shape[1], self.device
            )
        if push:
            self.history.push(noisy)
        if reset_ids.numel():
            self.history.fill(reset_ids, noisy[reset_ids])
        self.obs = TensorDict(
            {
                "policy": noisy,
                "history": self.history.flat().clone(),
                "privileged": self._group("privileged", self.cfg.privileged, s, cache)[1],
                "critic": self._group("critic", self.cfg.critic, s, cache)[1],
                "base_lin_vel": s.base_lin_vel_b.clone(),
                "policy_clean": clean,
            },
            batch_size=[self.num_envs],
        )
        return self.obs

    def _group(
        self, name: str, group: ObsGroup, s: EnvState, cache: dict[int, torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(clean, noisy) values of a group: its terms (scaled) concatenated, and the same plus
        each term's uniform noise when the group is noisy (else the clean tensor itself).
        ``cache`` holds the terms already evaluated for this state (groups share terms)."""
        parts = []
        for term in group.terms:
            if id(term) not in cache:
                value = term(s)
                cache[id(term)] = value * term.scale if term.scale != 1.0 else value
            parts.append(cache[id(term)])
        clean = torch.cat(parts, dim=-1)
        if not group.noisy:
            return clean, clean
        if name not in self._noise_scale:
            widths = torch.tensor([p.shape[1] for p in parts], device=self.device)
            amplitude = [term.noise if self.noise else 0.0 for term in group.terms]
            self._noise_scale[name] = torch.repeat_interleave(
                torch.tensor(amplitude, dtype=torch.float32, device=self.device), widths
            )
        noise = 2 * torch.rand(clean.shape, generator=self.generator, device=self.device) - 1
        return clean, clean + noise * self._noise_scale[name]

    def layout(self, s: EnvState) -> dict[str, list[tuple[str, int, int]]]:
        """Per group: (term name, first column, width) in column order (``policy_clean`` has the
        policy layout; ``history`` is H policy rows, oldest first)."""
        layout: dict[str, list[tuple[str, int, int]]] = {}
        for name in TASK_GROUPS:
            col = 0
            layout[name] = []
            for term in getattr(self.cfg, name).terms:
                width = int(term(s).shape[1])
                layout[name].append((term.name, col, width))
                col += width
        layout["policy_clean"] = layout["policy"]
        return layout

    def term(self, s: EnvState, group: str, term: str) -> torch.Tensor:
        """The columns (N, D) of one named term in the current observations of ``group``."""
        for name, start, width in self.layout(s)[group]:
            if name == term:
                return self.obs[group][:, start : start + width]
        raise KeyError(f"observation group '{group}' has no term '{term}'")

    def state_dict(self) -> dict[str, Any]:
        """History and current observations."""
        return {"history": self.history.buffer.clone(), "obs": self.obs.clone()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (after the env's first observation), onto this
        part's device."""
        self.history.buffer = state["history"].to(self.device, copy=True)
        self.obs = state["obs"].to(self.device).clone()
