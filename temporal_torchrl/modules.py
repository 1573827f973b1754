"""A ReLU whose compiled backward reads its float output instead of a saved boolean mask.

Eager, :func:`relu` is :func:`torch.relu`. Under :func:`torch.compile` its backward is
``grad * sign(output)``, computed from the output the next layer saves anyway, so the compiled
graph neither stores nor loads a ``bool`` tensor: inductor's CPU code handles ``bool`` tensors
element by element (ATen's ``Vectorized<bool>`` has no SIMD specialisation), which made saving
ReLU's mask cost more than the whole eager ReLU and the compiled SAC update slower than eager.
The measurements, before and after, are in ``CHANGELOG.md`` (2026-12-02, evening).

The gradient is ReLU's: ``grad`` where the output is positive, zero elsewhere (a zero there may
carry ``grad``'s sign, and a non-finite ``grad`` stays non-finite, as ``grad * 0`` does).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


class _ReLUFromOutput(torch.autograd.Function):
    @staticmethod
    def forward(x: Tensor) -> Tensor:
        return torch.relu(x)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        ctx.save_for_backward(output)

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (output,) = ctx.saved_tensors
        return grad * output.sign()  # output >= 0: sign is 1 where it passed, 0 where it did not


def relu(x: Tensor) -> Tensor:
    """max(x, 0): :func:`torch.relu` eager; under :func:`torch.compile`, a ReLU whose backward
    reads its output (no boolean mask in the compiled graph).

    Example:
        >>> x = torch.tensor([-1.0, 2.0], requires_grad=True)
        >>> y = torch.compile(relu)(x)
        >>> y.sum().backward()
        >>> y.tolist(), x.grad.tolist()
        ([0.0, 2.0], [0.0, 1.0])
    """
    return _ReLUFromOutput.apply(x) if torch.compiler.is_compiling() else torch.relu(x)


class ReLU(nn.Module):
    """:func:`relu` as a module: a drop-in :class:`torch.nn.ReLU` (no parameters, so a model's
    ``state_dict`` keys are unchanged), e.g. TorchRL ``MLP(activation_class=ReLU)``.

    Example:
        >>> ReLU()(torch.tensor([-1.0, 2.0])).tolist()
        [0.0, 2.0]
    """

    def forward(self, x: Tensor) -> Tensor:
        return relu(x)
