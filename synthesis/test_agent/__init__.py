"""The dynamic test agent (docs/method.md §7): game, GR(1) solver, counterexample loop.

Three words, three things (FlowTest never says plain "agent" for more than one of them):

* **system under test** (SUT) — the system being tested, driven by the user's policy or a
  learned one. It plays ``system_0`` in the environments; its policies live in :mod:`agents`
  (``agents/``: random, scripted, planning, PPO and GR(1)-synthesized SUTs, :mod:`agents.registry`).
* **test agent** — the test's own moving obstacle on agent problems: a second player on the
  places of ``T`` that stands in the system's way. Its transition system ``T_TA`` is
  :class:`synthesis.model.agent_system.TestAgent`; this package synthesizes its strategy
  (:mod:`~synthesis.test_agent.game`, :mod:`~synthesis.test_agent.gr1`,
  :mod:`~synthesis.test_agent.loop`) and tabulates and checks its controller
  (:mod:`~synthesis.test_agent.controller`, :mod:`~synthesis.test_agent.closed_loop`,
  :mod:`~synthesis.test_agent.realize`, which also holds the result, ``AgentSynthesis``).
* **tester** — whoever plays ``tester_0`` against the SUT: the synthesized test (cuts, or the
  test agent's controller) or a learned tester (:mod:`agents.testers`).

User-facing words keep their names: a problem of kind ``"agent"`` and the problem file's
``[environment.agent]`` table describe the test agent.
"""
