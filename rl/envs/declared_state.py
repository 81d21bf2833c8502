"""State declared once: a part names the attributes that evolve (``state_attributes``) and
:class:`DeclaredState` derives its ``state_dict`` / ``load_state_dict`` from that list, so save
and load cannot drift apart (the exact resume depends on them holding the same fields)."""

from __future__ import annotations

import copy
from typing import Any

import torch


class DeclaredState:
    """Mixin: ``state_dict`` holds each attribute named in ``state_attributes`` (tensors cloned,
    parts with a state of their own by their ``state_dict``, other values copied);
    ``load_state_dict`` restores them (tensors onto the device of the attribute they replace)."""

    state_attributes: tuple[str, ...] = ()

    def state_dict(self) -> dict[str, Any]:
        """The declared attributes' values."""
        return {name: _saved(getattr(self, name)) for name in self.state_attributes}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        for name in self.state_attributes:
            current = getattr(self, name)
            if isinstance(current, torch.Tensor):
                setattr(self, name, state[name].to(current.device, copy=True))
            elif hasattr(current, "load_state_dict"):
                current.load_state_dict(state[name])
            else:
                setattr(self, name, copy.deepcopy(state[name]))


def _saved(value: Any) -> Any:
    if isinstance(value, torch.Tensor):
        return value.clone()
    if hasattr(value, "state_dict"):
        return value.state_dict()
    return copy.deepcopy(value)
