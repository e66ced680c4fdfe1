"""FlowTest's agents: the systems under test that play a test, and the testers that play its side.

Every system under test is one :class:`~agents.base.Policy` (``reset(seed)``, ``act(observation,
info) -> action``), whatever made it: scripted planners (:mod:`agents.scripted`), a GR(1)
controller synthesized for the system objective (:mod:`agents.gr1_sut`), a trained PPO policy
(:mod:`agents.ppo`: native checkpoints and stable-baselines3 zips; the native trainer is
:mod:`agents.native_ppo`), or the user's own planner over a process boundary (:mod:`agents.external`:
``python:MODULE:NAME`` and ``cmd:COMMAND``). :mod:`agents.registry` names each one
(``--sut NAME``); :mod:`agents.testers` holds the testers of the two-player game. This package
imports nothing itself: torch loads only with a PPO policy.

Example::

    from agents.registry import make_policy
    import flowtest_env, gymnasium as gym

    env = gym.make("FlowTest-Maze2-v0")
    policy = make_policy("scripted:replanner", env)
"""
