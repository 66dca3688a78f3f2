"""The arithmetic of offline training updates (``--precision``): fp32, or bfloat16 under ``torch.autocast``."""

from __future__ import annotations

import torch

#: --precision values: auto (bf16 where it is measured faster, see :func:`resolve_precision`), fp32, bf16
PRECISIONS = ("auto", "fp32", "bf16")
#: the algorithms that train in bf16: d3rlpy 2.8.1's BC and CQL losses come out as bfloat16 scalars that its own
#: loss logging cannot convert (TypeError: unsupported ScalarType BFloat16)
BF16_ALGORITHMS = ("bcq", "dqn", "ddqn", "nfq")
#: --batch-size 0 (auto) per resolved precision: bf16 at 512 costs about what fp32 costs at 256 on a CPU with AMX
#: (Dallas Q3 expert BCQ: 41 s against 39 s for 4 000 updates) and draws twice the samples
AUTO_BATCH = {"fp32": 256, "bf16": 512}


def bf16_matrix_units() -> bool:
    """Whether this CPU multiplies bfloat16 matrices in hardware (AMX or AVX512-BF16); without them autocast in
    bfloat16 is emulated and slower than fp32."""
    try:
        caps = torch.cpu.get_capabilities()
    except (AttributeError, RuntimeError):  # an older torch: assume not
        return False
    return bool(caps.get("amx_bf16") or caps.get("avx512_bf16"))


def resolve_precision(precision: str, algorithm: str, device: str = "cpu") -> str:
    """``precision`` with ``auto`` resolved: bf16 for the algorithms that train in it on a CPU with bf16 matrix
    units, else fp32 (a GPU is not measured: fp32)."""
    if precision != "auto":
        return precision
    on_cpu = torch.device(device).type == "cpu"
    return "bf16" if algorithm in BF16_ALGORITHMS and on_cpu and bf16_matrix_units() else "fp32"


def update_autocast(precision: str, device: str = "cpu") -> torch.autocast:
    """The context every update of a training runs in: ``torch.autocast`` in bfloat16 on ``device``'s kind when
    ``precision`` is ``bf16`` (weights, gradients and optimiser state stay fp32), a disabled one for ``fp32``.

    The weight-cast cache is off: it lives as long as the context, so with it every update of the run would reuse the
    bfloat16 copies of the first update's weights (measured: the loss stayed flat, nothing was learnt).
    """
    enabled = precision == "bf16"
    return torch.autocast(torch.device(device).type, dtype=torch.bfloat16, enabled=enabled, cache_enabled=False)
