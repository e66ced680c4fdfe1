"""RLlib (new API stack): PPO for ``system_0`` of the PettingZoo parallel game, masked,
the synthesized test holding ``tester_0`` as a fixed RLModule that is never trained.

    python docs/recipes/rllib_recipe.py --steps 20000

RLlib 2.60 pins ``gymnasium==1.2.2`` while FlowTest's lock has 1.4, so it lives in a
venv of its own (docs/recipes.md, requirements/rllib.txt)::

    python3 -m venv .venv-rllib
    .venv-rllib/bin/pip install -r requirements/rllib.txt -e .

RLlib's action-masking module reads the Dict keys ``observations`` and ``action_mask``:
``obs_key="observations"`` names them so.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import ray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModule, RLModuleSpec
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.rllib.examples.rl_modules.classes.action_masking_rlm import ActionMaskingTorchRLModule
from ray.tune.registry import register_env

from flowtest_env import multiagent


def make_env(config: dict[str, Any]) -> ParallelPettingZooEnv:
    return ParallelPettingZooEnv(multiagent.parallel_env(test=config.get("test", "small-reactive"), obs_key="observations"))


class SynthesizedTesterRLM(RLModule):
    """The synthesized tester as an RLModule: the action from the tester's observation."""

    def setup(self) -> None:
        config = self.model_config
        assert isinstance(config, dict)
        self.tester = multiagent.SynthesizedTester(multiagent.raw_env(test=config["test"], obs_key="observations"))

    def _forward_inference(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        obs = batch[Columns.OBS]["observations"]
        return {Columns.ACTIONS: self.tester.actions(np.asarray(obs))}

    def _forward_exploration(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return self._forward_inference(batch, **kwargs)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        raise NotImplementedError("the synthesized tester is fixed: leave it out of policies_to_train")


def main(test: str = "small-reactive", steps: int = 4096, seed: int = 0) -> dict[str, float]:
    """Train the system for at least ``steps`` env steps; returns what happened."""
    ray.init(num_cpus=1, include_dashboard=False, ignore_reinit_error=True, log_to_driver=False)
    register_env("flowtest_ma", make_env)
    config = (
        PPOConfig()
        .environment("flowtest_ma", env_config={"test": test})
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .multi_agent(
            policies={"system", "tester"},
            policy_mapping_fn=lambda agent_id, *args, **kwargs: "system" if agent_id == multiagent.SYSTEM else "tester",
            policies_to_train=["system"],
        )
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={
                    "system": RLModuleSpec(module_class=ActionMaskingTorchRLModule, model_config={"head_fcnet_hiddens": [64]}),
                    "tester": RLModuleSpec(module_class=SynthesizedTesterRLM, model_config={"test": test}),
                }
            )
        )
        .training(train_batch_size_per_learner=256, minibatch_size=64, num_epochs=2, lr=3e-3)
        .debugging(seed=seed)
    )
    algo = config.build_algo()
    done, episodes, start = 0, 0, time.perf_counter()
    while done < steps:
        result = algo.train()
        done = int(result["env_runners"]["num_env_steps_sampled_lifetime"])
        episodes = int(result["env_runners"].get("num_episodes_lifetime", episodes))
    seconds = time.perf_counter() - start
    algo.stop()
    ray.shutdown()
    return {"steps": float(done), "episodes": float(episodes), "seconds": seconds, "steps_per_s": done / seconds}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--test", default="small-reactive")
    ap.add_argument("--steps", type=int, default=4096)
    a = ap.parse_args()
    print(main(a.test, a.steps))
