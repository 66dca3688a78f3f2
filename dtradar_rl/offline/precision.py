"""The arithmetic of offline training updates (``--precision``): fp32, or bfloat16 under ``torch.autocast``."""

from __future__ import annotations

import torch


def update_autocast(precision: str, device: str = "cpu") -> torch.autocast:
    """The context every update of a training runs in: ``torch.autocast`` in bfloat16 on ``device``'s kind when
    ``precision`` is ``bf16`` (weights, gradients and optimiser state stay fp32), a disabled one for ``fp32``.

    The weight-cast cache is off: it lives as long as the context, so with it every update of the run would reuse the
    bfloat16 copies of the first update's weights (measured: the loss stayed flat, nothing was learnt).
    """
    return torch.autocast(
        torch.device(device).type, dtype=torch.bfloat16, enabled=precision == "bf16", cache_enabled=False
    )
