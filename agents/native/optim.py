"""Adam over one flat buffer: every parameter of a network is a view into one float32
vector and every gradient a view into another, so the gradient clip is one norm and the
Adam step a handful of vector operations, whatever the number of layers
(:class:`FlatAdam`). It keeps :class:`torch.optim.Adam`'s rule (``betas`` 0.9, 0.999, bias
correction, ``eps`` added after the square root) and its ``param_groups[0]["lr"]``, which
the trainer anneals; and it does not import ``torch._dynamo``, as ``torch.optim``'s
optimizers do on their first construction (1-5 s of a short run's start on a loaded
machine).

Example::

    from agents.native.optim import FlatAdam
    opt = FlatAdam(agent.named_parameters(), lr=1e-3, eps=1e-5)
    opt.zero_grad()
    loss.backward()            # autograd accumulates into the flat gradient's views
    opt.clip_grad_norm(0.5)
    opt.step()
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import torch
from torch import nn


class FlatAdam:
    """Adam on parameters rebound as views of one flat buffer (:attr:`flat`), their
    gradients views of another (:attr:`grad`). ``named_params`` gives the order of the
    buffer (a network can put the layers it multiplies together next to each other:
    :meth:`view` then returns them as one matrix)."""

    def __init__(self, named_params: Iterable[tuple[str, nn.Parameter]], lr: float, eps: float = 1e-8, betas: tuple[float, float] = (0.9, 0.999)) -> None:
        params = list(named_params)
        if not params:
            raise ValueError("FlatAdam needs parameters")
        first = params[0][1]
        total = sum(p.numel() for _, p in params)
        self.flat = torch.empty(total, dtype=first.dtype, device=first.device)
        self.grad = torch.zeros_like(self.flat)
        self.offsets: dict[str, tuple[int, int]] = {}
        at = 0
        for name, p in params:
            n = p.numel()
            self.flat[at : at + n].copy_(p.detach().reshape(-1))
            p.data = self.flat[at : at + n].view_as(p)
            p.grad = self.grad[at : at + n].view_as(p)
            self.offsets[name] = (at, n)
            at += n
        self.params = [p for _, p in params]
        self.m = torch.zeros_like(self.flat)
        self.v = torch.zeros_like(self.flat)
        self.betas = (float(betas[0]), float(betas[1]))
        self.eps = float(eps)
        self.steps = 0
        self.param_groups = [{"lr": float(lr)}]

    def view(self, names: Iterable[str], shape: tuple[int, ...], grad: bool = False) -> torch.Tensor:
        """The parameters ``names``, adjacent in the buffer in this order, as one tensor of
        ``shape`` (``grad``: their gradients).

        Raises
        ------
        ValueError
            If they are not adjacent.
        """
        names = list(names)
        start, n = self.offsets[names[0]]
        at = start + n
        for name in names[1:]:
            o, k = self.offsets[name]
            if o != at:
                raise ValueError(f"{name} does not follow {names[0]} in the flat buffer")
            at += k
        buf = self.grad if grad else self.flat
        return buf[start:at].view(shape)

    def zero_grad(self) -> None:
        """Zero every gradient (in place: the views stay)."""
        self.grad.zero_()

    def clip_grad_norm(self, max_norm: float) -> torch.Tensor:
        """Scale the gradients to a total 2-norm of at most ``max_norm`` (as
        :func:`torch.nn.utils.clip_grad_norm_`); returns the norm before."""
        norm: torch.Tensor = torch.linalg.vector_norm(self.grad)
        self.grad.mul_(torch.clamp(max_norm / (norm + 1e-6), max=1.0))
        return norm

    def step(self) -> None:
        """One Adam step on the gradients."""
        b1, b2 = self.betas
        self.steps += 1
        lr = self.param_groups[0]["lr"]
        self.m.lerp_(self.grad, 1 - b1)
        self.v.mul_(b2).addcmul_(self.grad, self.grad, value=1 - b2)
        bc1, bc2 = 1 - b1**self.steps, 1 - b2**self.steps
        denom = (self.v.sqrt() / math.sqrt(bc2)).add_(self.eps)
        self.flat.addcdiv_(self.m, denom, value=-lr / bc1)


__all__ = ["FlatAdam"]
