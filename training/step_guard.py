"""The guard a training loop runs between ``backward()`` and ``optimizer.step()``: a NaN or infinite loss or
gradient stops the run there, before the optimiser spreads it to every weight.

Why here: AdamW turns one NaN gradient into NaN weights, the network then answers NaN, the held-out means drop
those answers (``np.nanmean``) and the run saved the NaN weights with exit 0. ``training.learnt_fill`` (the
painter) and ``training.skeleton_prior`` share this guard; ``training.train`` checks its named loss terms and
the norm it clips by (its :class:`training.train.NonFiniteLoss` is a :class:`TrainingDiverged` too).
"""
from __future__ import annotations

import math

import torch


class TrainingDiverged(FloatingPointError):
    """A training step's loss or gradients are NaN or infinite; raised before the update (the message names the
    step), so no NaN weights are trained on, scored or saved."""


def finite_step(loss: torch.Tensor, net: torch.nn.Module, step: int) -> float:
    """``loss``'s value once it and ``net``'s gradients are finite, else :class:`TrainingDiverged` naming
    ``step``. Call it after ``loss.backward()`` and before ``optimizer.step()``."""
    value = float(loss.detach())
    if not math.isfinite(value):
        raise TrainingDiverged(f"step {step}: non-finite loss ({value:g}); the weights were not updated")
    # a finite loss can still have one: the slope of sqrt at 0, an overflow in the backward pass
    if not all(bool(torch.isfinite(p.grad).all()) for p in net.parameters() if p.grad is not None):
        raise TrainingDiverged(f"step {step}: non-finite gradient of a finite loss ({value:.6g}); the weights "
                               f"were not updated")
    return value
