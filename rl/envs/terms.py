"""The named terms a task is made of: observation, reward and termination terms.

Each term is a frozen dataclass naming one pure function over the batched :class:`EnvState` plus
its parameters: ``func(state, **params) -> Tensor``. A task lists its terms once (the name is the
term's only identity: it is the ``Reward/<name>`` log key, the observation-term address in tests,
the ``--task-reward-weight NAME=W`` flag key). Generic env code evaluates the lists; it never
knows which task it runs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import torch

from rl.envs.state import EnvState

TermFunc = Callable[..., torch.Tensor]
"""``func(state: EnvState, **params) -> Tensor``: (N, D) for observations, (N,) otherwise."""


@dataclass(frozen=True)
class Term:
    """A named pure function of the env state with fixed keyword parameters."""

    name: str  # unique within its list; log key and address of the term [-]
    func: TermFunc  # pure function (state, **params) -> tensor
    params: Mapping[str, Any] = field(default_factory=dict)  # keyword arguments of func

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("_", "").isalnum():
            raise ValueError(f"term name must be a non-empty identifier, got {self.name!r}")
        object.__setattr__(self, "params", dict(self.params))  # own copy: the caller's may change

    def __call__(self, state: EnvState) -> torch.Tensor:
        """Evaluate the term on a batch state."""
        return self.func(state, **self.params)

    def describe(self) -> str:
        """``name = module.func(params)`` for logs and ``list-tasks``."""
        args = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.name} = {self.func.__module__}.{self.func.__qualname__}({args})"


@dataclass(frozen=True)
class ObsTerm(Term):
    """An observation term: (N, D) values, scaled, then (in noisy groups) uniform noise added."""

    scale: float = 1.0  # multiplies the term's value [-]
    noise: float = 0.0  # half-width of the uniform noise added after scaling, in the term's unit


@dataclass(frozen=True)
class RewardTerm(Term):
    """A reward term: ``weight * func(state) * dt`` per step, logged as ``Reward/<name>``."""

    weight: float = 1.0  # weight (negative for penalties); the env multiplies by the step dt [-]


@dataclass(frozen=True)
class TerminationTerm(Term):
    """A failure condition (N,) bool; any true term ends the episode as a failure."""


@dataclass(frozen=True)
class ObsGroup:
    """An observation group: named terms concatenated in order, optionally noisy."""

    terms: tuple[ObsTerm, ...]  # terms in column order
    noisy: bool = False  # add each term's noise (the env's noise switch must be on too)

    def names(self) -> tuple[str, ...]:
        """Term names in column order."""
        return tuple(t.name for t in self.terms)


def check_unique(kind: str, terms: tuple[Term, ...]) -> None:
    """Raise if two terms of one list share a name (a name must address one term)."""
    seen: set[str] = set()
    for term in terms:
        if term.name in seen:
            raise ValueError(f"{kind} term name '{term.name}' appears twice; names must be unique")
        seen.add(term.name)


def sum_rewards(
    terms: tuple[RewardTerm, ...],
    state: EnvState,
    step_dt_s: float,
    extra: dict[str, torch.Tensor] | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The step reward (N,): ``weight * term(state) * dt`` summed over ``terms``, plus ``extra``
    terms already weighted (e.g. the less-assist reward); and ``Reward/<name>`` means to log
    (0-dim tensors on the state's device: the env sends its log to the host in one batch)."""
    names = [t.name for t in terms]
    values = [t(state) * (t.weight * step_dt_s) for t in terms]
    for name, value in (extra or {}).items():
        names.append(name)
        values.append(value)
    weighted = torch.stack(values)  # (terms, N)
    means = weighted.mean(dim=1)
    return weighted.sum(dim=0), {f"Reward/{k}": v for k, v in zip(names, means, strict=True)}


def any_failure(
    terms: tuple[TerminationTerm, ...], state: EnvState
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Failures (N,) bool, any of ``terms`` true (none: all False), and each term's share of
    failing envs as ``Termination/<name>`` to log (0-dim tensors, as :func:`sum_rewards`'s)."""
    per_term = [term(state) for term in terms]
    if not per_term:
        return torch.zeros_like(state.terminated), {}
    log = {f"Termination/{t.name}": v.float().mean() for t, v in zip(terms, per_term, strict=True)}
    return torch.stack(per_term).any(dim=0), log
