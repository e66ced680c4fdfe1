"""The MLP's PPO gradient written out by hand: the forward pass of both heads, the clipped
loss of :func:`agents.native.core.ppo_loss` and its gradient in a few matrix products,
straight into the flat gradient of :class:`agents.native.optim.FlatAdam`, with no autograd
graph.

Why: on the CPU, a minibatch of a small network is a few milliseconds of arithmetic and
several more of autograd and module overhead (the graph, one Python call per layer and per
loss term); the sample-efficient settings (many epochs of small minibatches) pay that
overhead many times per rollout. The arithmetic is the same: the actor's and the critic's
first layers are one product (their weights adjacent in the flat buffer), the rest layer by
layer. ``tests/agents/test_native_fused.py`` holds the gradient to autograd's on the same
loss.

The loss (``w``: the samples' weights, ``n = max(sum w, 1)``; ``A`` the advantages
normalized over the weighted samples; ``r = exp(log pi(a) - log pi_old(a))``)::

    L = sum(w max(-A r, -A clip(r, 1-e, 1+e))) / n + c_v sum(w (V - R)^2) / (2 n) - c_e sum(w H) / n

and its gradient with respect to the masked logits ``z`` and the values ``V``::

    dL/dr   = -A where -A r >= -A clip(r) (the unclipped term is the larger), else 0
    dL/dz_j = w/n [dL/dr r (1[j = a] - p_j) + c_e p_j (log p_j + H)]   (0 for an illegal j)
    dL/dV   = c_v w (V - R) / n

Example::

    opt = FlatAdam(agent.flat_order(), lr=1e-3, eps=1e-5)
    fused = FusedMLP(agent, opt)
    fused.gradient(args, minibatch)        # writes opt.grad
    opt.clip_grad_norm(args.max_grad_norm); opt.step()
"""

from __future__ import annotations

import torch

from .agent import MASKED_LOGIT, tanh
from .args import NativeArgs
from .batch import Minibatch
from .mlp import MLPAgent
from .optim import FlatAdam

Layer = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]
"""A linear layer's weight and bias, and their gradients (views of the flat buffers)."""


class FusedMLP:
    """The PPO gradient of an :class:`MLPAgent` whose parameters live in ``opt`` (built
    with :meth:`MLPAgent.flat_order`, so the two first layers are one matrix).

    Raises
    ------
    ValueError
        If the first layers are not adjacent in ``opt``'s buffer.
    """

    def __init__(self, agent: MLPAgent, opt: FlatAdam) -> None:
        self.agent, self.opt = agent, opt
        d, h = agent.obs_size, agent.first_width
        self.h = h
        names = {head: agent.linear_names(head) for head in ("actor", "critic")}
        weights = [names["actor"][0][0], names["critic"][0][0]]
        biases = [names["actor"][0][1], names["critic"][0][1]]
        self.first: Layer = (
            opt.view(weights, (2 * h, d)),
            opt.view(biases, (2 * h,)),
            opt.view(weights, (2 * h, d), grad=True),
            opt.view(biases, (2 * h,), grad=True),
        )
        params = dict(agent.named_parameters())
        self.heads: dict[str, list[Layer]] = {}
        for head, layers in names.items():
            self.heads[head] = []
            for wname, bname in layers[1:]:
                wt, bs = params[wname], params[bname]
                self.heads[head].append((wt, bs, opt.view([wname], tuple(wt.shape), grad=True), opt.view([bname], tuple(bs.shape), grad=True)))

    def _forward(self, x: torch.Tensor) -> tuple[torch.Tensor, dict[str, list[torch.Tensor]], dict[str, torch.Tensor]]:
        """The first layers' output, each head's activations (the input of each later layer) and outputs."""
        w, b, _, _ = self.first
        first = tanh(torch.addmm(b, x, w.t()))
        h = self.h
        acts: dict[str, list[torch.Tensor]] = {"actor": [first[:, :h]], "critic": [first[:, h:]]}
        outs: dict[str, torch.Tensor] = {}
        for head, layers in self.heads.items():
            a = acts[head][0]
            for k, (wt, bs, _, _) in enumerate(layers):
                y = torch.addmm(bs, a, wt.t())
                if k == len(layers) - 1:
                    outs[head] = y
                else:
                    a = tanh(y)
                    acts[head].append(a)
        return first, acts, outs

    def gradient(self, args: NativeArgs, mb: Minibatch, want_info: bool = False) -> dict[str, torch.Tensor]:
        """Write the gradient of the PPO loss on ``mb`` (a feed-forward minibatch) into
        the optimizer's flat gradient, overwriting it. Returns the loss terms as tensors
        when ``want_info`` (``{}`` otherwise: reading them costs a synchronisation)."""
        with torch.no_grad():
            return self._gradient(args, mb, want_info)

    def _gradient(self, args: NativeArgs, mb: Minibatch, want_info: bool) -> dict[str, torch.Tensor]:
        x = mb.obs
        first, acts, outs = self._forward(x)
        if mb.all_valid:  # every sample counts once: no weights to apply (a feed-forward minibatch)
            n: torch.Tensor | float = float(x.shape[0])
            wn: torch.Tensor | float = 1.0 / x.shape[0]
            var, mean = torch.var_mean(mb.adv, correction=0)
            adv = (mb.adv - mean) * torch.rsqrt(var + 1e-8)
            logits = outs["actor"]
        else:
            w = mb.weight.to(x.dtype)
            n = w.sum().clamp(min=1.0)
            wn = w / n
            valid = w > 0
            mean = (mb.adv * w).sum() / n
            std = torch.sqrt((((mb.adv - mean) ** 2) * w).sum() / n + 1e-8)
            adv = torch.where(valid, (mb.adv - mean) / std, torch.zeros_like(mb.adv))
            logits = outs["actor"]
        legal = mb.masks | ~mb.masks.any(dim=-1, keepdim=True)
        z = torch.where(legal, logits, MASKED_LOGIT)
        logp_all = torch.log_softmax(z, dim=-1)
        p = logp_all.exp()
        logp = logp_all.gather(-1, mb.actions.unsqueeze(-1)).squeeze(-1)
        delta = logp - mb.logprobs
        ratio = torch.exp(delta if mb.all_valid else torch.where(valid, delta, torch.zeros_like(delta)))
        unclipped, clipped = -adv * ratio, -adv * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)
        # dL/dlogp, then dL/dz = dL/dlogp (onehot - p) + c_e w/n p (logp + H); an illegal j has p_j = 0
        # and is not the action, so its entry is 0 (logp_j is finite: -1e8 less the log-sum)
        g_logp = torch.where(unclipped >= clipped, -adv * ratio, 0.0) * wn
        entropy = -(p * logp_all).sum(-1)
        g_z = (logp_all + entropy.unsqueeze(-1)).mul_(p).mul_(args.ent_coef * (wn.unsqueeze(-1) if isinstance(wn, torch.Tensor) else wn))
        g_z.addcmul_(g_logp.unsqueeze(-1), p, value=-1.0)
        g_z.scatter_add_(-1, mb.actions.unsqueeze(-1), g_logp.unsqueeze(-1))
        values = outs["critic"].squeeze(-1)
        g_v = ((values - mb.returns) * (wn * args.vf_coef)).unsqueeze(-1)
        g_first = torch.empty_like(first)
        for head, g, part in (("actor", g_z, slice(0, self.h)), ("critic", g_v, slice(self.h, 2 * self.h))):
            layers = self.heads[head]
            for k in range(len(layers) - 1, -1, -1):
                wt, _, gw, gb = layers[k]
                a_in = acts[head][k]
                torch.mm(g.t(), a_in, out=gw)
                torch.sum(g, dim=0, out=gb)
                g = g @ wt
                g = g.addcmul_(g * a_in, a_in, value=-1.0)  # g (1 - a^2): tanh's derivative
            g_first[:, part] = g
        _, _, gw, gb = self.first
        torch.mm(g_first.t(), x, out=gw)
        torch.sum(g_first, dim=0, out=gb)
        if not want_info:
            return {}
        w_all = mb.weight.to(x.dtype)
        pg_loss = (torch.maximum(unclipped, clipped) * w_all).sum() / n
        v_loss = 0.5 * (((values - mb.returns) ** 2) * w_all).sum() / n
        kl = (((ratio - 1) - torch.log(ratio.clamp(min=1e-12))) * w_all).sum() / n
        return {"policy_loss": pg_loss, "value_loss": v_loss, "entropy": (entropy * w_all).sum() / n, "approx_kl": kl}


__all__ = ["FusedMLP"]
