"""Tianshou: DQN for ``system_0`` of the PettingZoo AEC game, masked, the synthesized test
holding ``tester_0`` as a fixed policy (Tianshou's multi-agent algorithm over ``PettingZooEnv``).

    python docs/recipes/tianshou_aec.py --steps 20000

Needs ``pip install -c requirements/lock.txt -e '.[rl,recipes]'``. Tianshou's
``PettingZooEnv`` asserts that all agents share one observation and one action space:
``same_spaces=True`` pads them (the padding actions never in the mask); it reads the
``observation`` and ``action_mask`` entries and hands the policies ``obs.obs`` and
``obs.mask``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any, cast

import numpy as np
import torch
from tianshou.algorithm.algorithm_base import Policy as BasePolicy
from tianshou.algorithm.modelfree.dqn import DQN, DiscreteQLearningPolicy
from tianshou.algorithm.multiagent.marl import MultiAgentOffPolicyAlgorithm
from tianshou.algorithm.optim import AdamOptimizerFactory
from tianshou.algorithm.random import MARLRandomDiscreteMaskedOffPolicyAlgorithm
from tianshou.data import Batch, Collector, VectorReplayBuffer
from tianshou.env import DummyVectorEnv, PettingZooEnv
from tianshou.utils.net.common import Net
from tianshou.utils.torch_utils import policy_within_training_step

from flowtest_env import multiagent


def make_env(test: str, **options: Any) -> PettingZooEnv:
    return PettingZooEnv(multiagent.env(test=test, same_spaces=True, **options))


class FixedTester(MARLRandomDiscreteMaskedOffPolicyAlgorithm):
    """The synthesized tester as an algorithm that learns nothing (Tianshou's own
    fixed random agent, with the synthesized strategy as its policy)."""

    class Policy(BasePolicy):
        def __init__(self, action_space: Any, tester: multiagent.SynthesizedTester) -> None:
            super().__init__(action_space=action_space)
            self.tester = tester

        def forward(self, batch: Any, state: Any = None, **kwargs: Any) -> Any:
            return Batch(act=self.tester.actions(np.asarray(batch.obs.obs)))

    def __init__(self, action_space: Any, tester: multiagent.SynthesizedTester) -> None:
        super(MARLRandomDiscreteMaskedOffPolicyAlgorithm, self).__init__(policy=self.Policy(action_space, tester))


def main(test: str = "small-reactive", steps: int = 8192, num_envs: int = 8, seed: int = 0, **options: Any) -> dict[str, float]:
    """Train the system for ``steps`` env steps (both agents' turns); ``options`` go to the
    env (``max_cycles``, ...); returns what happened."""
    torch.manual_seed(seed)
    np.random.seed(seed)
    env = make_env(test, **options)
    tester = multiagent.SynthesizedTester(env.env)
    n_obs = int(np.prod(env.observation_space["observation"].shape))
    n_act = int(env.action_space.n)
    learner = DQN(
        policy=DiscreteQLearningPolicy(
            model=Net(state_shape=n_obs, action_shape=n_act, hidden_sizes=[64, 64]), action_space=env.action_space, eps_training=0.1
        ),
        optim=AdamOptimizerFactory(lr=1e-3),
        gamma=0.99,
        target_update_freq=100,
    )
    fixed = FixedTester(env.action_space, tester)
    by_agent = {multiagent.TESTER: fixed, multiagent.SYSTEM: learner}
    algorithm = MultiAgentOffPolicyAlgorithm(algorithms=[by_agent[a] for a in env.agents], env=env)
    envs = DummyVectorEnv([lambda: make_env(test, **options) for _ in range(num_envs)])
    envs.seed(seed)
    collector: Collector[Any] = Collector(algorithm, envs, VectorReplayBuffer(20_000, num_envs), exploration_noise=True)
    collector.reset()
    stats = {"steps": 0.0, "episodes": 0.0, "updates": 0.0}
    start = time.perf_counter()
    while stats["steps"] < steps:
        collected = collector.collect(n_step=num_envs * 16)
        stats["steps"] += collected.n_collected_steps
        stats["episodes"] += collected.n_collected_episodes
        with policy_within_training_step(algorithm.policy):
            for _ in range(4):
                algorithm.update(buffer=cast(Any, collector.buffer), sample_size=64)
                stats["updates"] += 1
    stats["seconds"] = time.perf_counter() - start
    stats["steps_per_s"] = stats["steps"] / stats["seconds"]
    return stats


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--test", default="small-reactive")
    ap.add_argument("--steps", type=int, default=8192)
    a = ap.parse_args()
    torch.set_num_threads(1)
    print(main(a.test, a.steps))
