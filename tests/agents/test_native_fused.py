"""The native trainer's update arithmetic (agents/native/fused.py, agents/native/optim.py):
the hand-written MLP gradient equals autograd's on the same PPO loss, the flat Adam takes
torch's Adam steps, autograd accumulates into the flat gradient, and the fused update
never trains on an autoreset step."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from agents.native.args import NativeArgs  # noqa: E402
from agents.native.batch import Minibatch  # noqa: E402
from agents.native.core import collect_rollout, ppo_loss, ppo_update  # noqa: E402
from agents.native.fused import FusedMLP  # noqa: E402
from agents.native.mlp import MLPAgent  # noqa: E402
from agents.native.networks import make_agent  # noqa: E402
from agents.native.optim import FlatAdam  # noqa: E402


def _minibatch(n: int, d: int, a: int, seed: int, weights: bool = False) -> Minibatch:
    g = torch.Generator().manual_seed(seed)
    masks = torch.rand(n, a, generator=g) < 0.6
    masks[0] = False  # a row with no legal action keeps its logits
    masks[1] = torch.tensor([True] + [False] * (a - 1))  # one legal action: entropy 0
    actions = torch.argmax(torch.rand(n, a, generator=g) * masks, dim=1)
    weight = (torch.rand(n, generator=g) < 0.8) if weights else torch.ones(n, dtype=torch.bool)
    return Minibatch(
        obs=(torch.rand(n, d, generator=g) < 0.3).float(),
        masks=masks,
        actions=actions,
        logprobs=torch.log(torch.rand(n, generator=g) * 0.6 + 0.2),
        adv=torch.randn(n, generator=g),
        returns=torch.randn(n, generator=g),
        weight=weight,
        h0=torch.zeros(n, 0),
        starts=torch.zeros(n, dtype=torch.bool),
        all_valid=not weights,
    )


@pytest.mark.parametrize("hidden", [(8,), (16, 12), (8, 8, 8)])
@pytest.mark.parametrize("weights", [False, True])
def test_the_fused_gradient_is_autograds(hidden: tuple[int, ...], weights: bool) -> None:
    """Both paths: every sample valid (a feed-forward minibatch: no weights applied) and
    weighted samples (0 for an autoreset step)."""
    torch.manual_seed(0)
    agent = MLPAgent(20, 5, hidden)
    twin = copy.deepcopy(agent)
    args = NativeArgs(clip_coef=0.2, ent_coef=0.05, vf_coef=0.7)
    mb = _minibatch(64, 20, 5, seed=1, weights=weights)
    # autograd on the reference loss
    logits, values = twin.replay(mb.obs, mb.h0, mb.starts)
    loss, info = ppo_loss(args, mb, logits, values)
    loss.backward()
    want = {k: p.grad.clone() for k, p in twin.named_parameters()}
    # by hand, into the flat gradient
    opt = FlatAdam(agent.flat_order(), lr=1e-3)
    got_info = FusedMLP(agent, opt).gradient(args, mb, want_info=True)
    for k, p in agent.named_parameters():
        torch.testing.assert_close(p.grad, want[k], rtol=1e-4, atol=1e-6, msg=k)
    for k, v in info.items():
        assert float(got_info[k]) == pytest.approx(v, rel=1e-5, abs=1e-7)
    # ... and the check can fail: another clip range gives another gradient
    FusedMLP(agent, opt).gradient(NativeArgs(clip_coef=0.01, ent_coef=0.05, vf_coef=0.7), mb)
    assert any(not torch.allclose(p.grad, want[k], rtol=1e-4, atol=1e-6) for k, p in agent.named_parameters())


def test_flat_adam_takes_torchs_adam_steps_and_autograd_fills_its_gradient() -> None:
    torch.manual_seed(0)
    agent = make_agent(12, 4, (10,), "gru", 6)
    twin = copy.deepcopy(agent)
    ref = torch.optim.Adam(twin.parameters(), lr=1e-2, eps=1e-5)
    opt = FlatAdam(agent.flat_order(), lr=1e-2, eps=1e-5)
    x, starts = torch.rand(5, 3, 12), torch.zeros(5, 3, dtype=torch.bool)
    for step in range(4):
        for net, o in ((agent, opt), (twin, ref)):
            logits, values = net.replay(x, net.initial_state(3, torch.device("cpu")), starts)
            loss = (logits**2).mean() + values.mean()
            o.zero_grad()
            loss.backward()
            if o is opt:
                assert float(opt.grad.abs().sum()) > 0  # autograd accumulated into the views
                opt.clip_grad_norm(0.5)
            else:
                torch.nn.utils.clip_grad_norm_(twin.parameters(), 0.5)
            o.step()
        for (k, p), q in zip(agent.named_parameters(), twin.parameters(), strict=True):
            torch.testing.assert_close(p, q, rtol=1e-5, atol=1e-6, msg=f"step {step}: {k}")
    opt.param_groups[0]["lr"] = 0.0  # the trainer anneals it there
    before = opt.flat.clone()
    opt.step()
    assert torch.equal(opt.flat, before)
    with pytest.raises(ValueError, match="does not follow"):
        opt.view(["gru.bias_hh", "encoder.0.weight"], (1,))


def test_the_fused_update_never_trains_on_an_autoreset_step() -> None:
    """Garbage at the autoreset steps leaves the fused update bit-for-bit the same; the
    same garbage at one valid step changes it."""
    import gymnasium as gym

    from agents.native.core import Runner
    from flowtest_env.encoding import make_encoder
    from flowtest_env.wrappers import shared_position_slice

    env: Any = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=4, vectorization_mode="vector_entry_point", max_steps=3)
    torch.manual_seed(0)
    where = shared_position_slice([make_encoder(g, "flat") for g in env.unwrapped.games])
    agent = make_agent(int(env.single_observation_space.shape[0]) + where.stop - where.start, 5, (16,))
    args = NativeArgs(num_envs=4, num_steps=12, num_minibatches=2, update_epochs=2, hidden=(16,))
    runner = Runner(env, agent, where, torch.device("cpu"), 0)
    collect_rollout(runner, 12)
    r = collect_rollout(runner, 12)
    inv = ~r.valid
    assert inv.sum() >= 4
    bad = copy.copy(r)
    bad.actions = torch.where(inv, (r.actions + 1) % 5, r.actions)
    bad.logprobs = torch.where(inv, torch.full_like(r.logprobs, -50.0), r.logprobs)
    bad.rewards = torch.where(inv, torch.full_like(r.rewards, 1e3), r.rewards)
    bad.masks = torch.where(inv.unsqueeze(-1), torch.ones_like(r.masks), r.masks)
    worse = copy.copy(r)
    k = int(np.flatnonzero(r.valid.numpy().reshape(-1))[0])
    worse.rewards = r.rewards.clone().reshape(-1)
    worse.rewards[k] = 1e3
    worse.rewards = worse.rewards.reshape(r.rewards.shape)
    out = []
    for rollout in (r, bad, worse):
        a = copy.deepcopy(agent)
        opt = FlatAdam(a.flat_order(), lr=1e-2)
        ppo_update(a, opt, args, rollout, torch.Generator().manual_seed(1))
        out.append(opt.flat.clone())
    assert torch.equal(out[0], out[1])
    assert not torch.equal(out[0], out[2])
