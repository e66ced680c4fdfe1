"""The caps on what a test may use (``max_walls``, ``max_doors``, ``max_restrictions``;
:attr:`~synthesis.routing.options.MilpOptions.caps`), rows of the routing model
(:class:`~synthesis.routing.model.CapRows`), and what is done around them, one job a module:

* :mod:`.messages` — what each cap counts and how a message says it (:data:`~.messages.CAP_NOUNS`,
  :func:`~.messages.caps_text`), and :class:`~.messages.CapsTimeout`, the time limit that ends a
  capped solve with neither a test nor a proof;
* the lower bounds, each a proof that every test needs more than a cap allows:
  :mod:`.bypasses` (walks around the test objective that share no item the cap counts,
  :func:`~.bypasses.disjoint_bypasses`; the same with the route every test leaves open spared,
  :func:`~.bypasses.routed_bypasses`) and :mod:`.separations` (what a test must close under one
  history the system must pass while leaving it a way to its goal:
  :class:`~.separations.HistorySeparations`);
* :mod:`.refusal` — a cap below what any test needs refused before the solve, by those bounds
  (:func:`~.refusal.check_caps_reachable`);
* :mod:`.start` — a first test within the caps for phase 1 to start from and fall back on, where
  the routing heuristic's test is over a cap (:func:`~.start.capped_guess`,
  :func:`~.start.start_within_caps`), and the local search that closes a test's bypasses with
  fewer items (:func:`~.start.fewer_items`);
* :mod:`.fewest` — what to say where no test fits: the fewest items a test needs
  (:func:`~.fewest.fewest_within`, the routing model's own optimum, solved by a backend of
  :data:`~synthesis.routing.solve.SOLVERS` through its ``least`` capability) and a cap that does
  give a test (:func:`~.fewest.found_with`).

The package imports nothing itself: the backends' phase 1 import :mod:`.start` alone.
"""
