"""Volume compositing of colour, heatmaps and depth with one set of weights.

ENeRF's convention: ``alpha_i = 1 - exp(-sigma_i)`` (no interval length) and
``T_i = prod_{j<i} (1 - alpha_j + 1e-10)``. The product is computed as
``exp(exclusive_cumsum(log(exp(-sigma) + 1e-10)))`` (``log(1 - alpha + 1e-10)``
written without the cancellation in ``1 - (1 - exp(-sigma))``), which exports
to ONNX (no cumprod) and stays finite for every ``sigma >= 0``:

* ``sigma = 0``: alpha 0, weights 0, the ray shows the background.
* ``sigma`` huge (1e30, inf): sigma is clamped to ``SIGMA_CLAMP`` first, so
  ``exp(-sigma)`` is a normal float, the log is >= log(1e-10), and the clamp's
  zero gradient beyond it keeps backward free of ``inf * 0``.
"""
from __future__ import annotations

import torch
from torch import Tensor

#: Densities above this are fully opaque anyway (exp(-60) ~ 1e-26); clamping keeps every exp/log finite.
SIGMA_CLAMP = 60.0
TRANSMITTANCE_EPS = 1e-10


def compositing_weights(sigma: Tensor, dim: int = -1) -> Tensor:
    """Per-sample weights from densities ordered near to far along ``dim`` (same shape as ``sigma``)."""
    if sigma.dtype in (torch.float16, torch.bfloat16):
        # In float16 exp(-sigma) underflows to 0 from sigma ~17 and the 1e-10 rounds to 0, so the log is -inf
        # and its gradient NaN; bfloat16 keeps the range but not the precision. Composite in float32 (a branch
        # on the dtype at trace time: the float32 graphs are unchanged).
        return compositing_weights(sigma.float(), dim).to(sigma.dtype)
    s = torch.clamp(sigma, min=0.0, max=SIGMA_CLAMP)
    e = torch.exp(-s)
    alpha = 1.0 - e
    log_t = torch.log(e + TRANSMITTANCE_EPS)
    n = sigma.shape[dim]
    if n == 1:
        return alpha
    csum = torch.cumsum(log_t, dim=dim)
    exclusive = torch.cat([torch.zeros_like(csum.narrow(dim, 0, 1)), csum.narrow(dim, 0, n - 1)], dim=dim)
    return alpha * torch.exp(exclusive)


def composite(weights: Tensor, values: Tensor, dim: int = -1) -> Tensor:
    """``weights`` ``(..., N, ...)``, channels-first ``values`` ``(C, ..., N, ...)`` -> ``(C, ...)``.

    ``dim`` is the sample axis counted from the end (negative), the same for both.
    """
    return (weights * values).sum(dim=dim)


def render_rays(sigma: Tensor, z: Tensor, rgb: Tensor | None, heat: Tensor | None,
                background: float = 0.0, dim: int = -1) -> dict[str, Tensor]:
    """Composite one set of samples (samples on axis ``dim`` < 0, value channels first).

    Args:
        sigma: ``(..., N, ...)`` densities, near to far along ``dim``; z: sample depths, same shape;
        rgb: ``(3, *sigma.shape)`` or None; heat: ``(J, *sigma.shape)`` or None.

    Returns:
        ``weights`` (sigma's shape), ``acc`` and ``depth`` (sigma's shape without ``dim``; depth is the
        expected depth of what the ray hits, ``sum w z / max(acc, 1e-6)``), ``rgb`` ``(3, ...)`` over
        ``background`` and ``heatmaps`` ``(J, ...)``.
    """
    if dim >= 0:
        raise ValueError("dim must be negative (counted from the end)")
    w = compositing_weights(sigma, dim)
    acc = w.sum(dim=dim)
    out = {"weights": w, "acc": acc, "depth": (w * z).sum(dim=dim) / torch.clamp(acc, min=1e-6)}
    if rgb is not None:
        out["rgb"] = composite(w, rgb, dim) + (1.0 - acc) * background
    if heat is not None:
        out["heatmaps"] = composite(w, heat, dim)
    return out


__all__ = ["compositing_weights", "composite", "render_rays", "SIGMA_CLAMP"]
