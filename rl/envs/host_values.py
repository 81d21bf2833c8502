"""What a step needs on the host, brought there in one transfer: on a GPU every read of a device
value (``float(t)``, ``t.tolist()``, ``t.nonzero()``, a boolean-mask index) waits for the device,
so the env gathers its log scalars, the physics' fault flags and its done mask, and reads them
once (:func:`to_host`). On the CPU the values are the same ones ``float(t)`` would give, bit for
bit (a float32 or integer value is exact in float64)."""

from __future__ import annotations

import torch


def to_host(
    values: dict[str, torch.Tensor | float], rows: torch.Tensor
) -> tuple[dict[str, float], torch.Tensor]:
    """``values`` with every 0-dim tensor replaced by its Python float (the other entries kept,
    the key order too), and the indices (M,) of the set rows of the mask ``rows`` (N,) bool (on
    its device), from one device-to-host copy."""
    keys = [k for k, v in values.items() if isinstance(v, torch.Tensor)]
    parts = [values[k].detach().reshape(1).double() for k in keys]
    host = torch.cat([*parts, rows.detach().reshape(-1).double()]).cpu()
    fetched = dict(zip(keys, host[: len(keys)].tolist(), strict=True))
    out = {k: fetched[k] if k in fetched else float(v) for k, v in values.items()}
    return out, host[len(keys) :].nonzero().flatten().to(rows.device)
