"""The routing MILP of docs/method.md §5 (and the MILP-agent options of §7): the least-restrictive
cuts that route every successful run through the test objective without trapping the system.

Layout, by role:

* :mod:`.options` — :class:`~.options.MilpOptions`, the options of one solve;
* :mod:`.groups` — what the model is built on: the cut groups and the walls and doors they
  stand for (:func:`~.groups.cut_groups`); :mod:`.edges` — the model's edges of G and the
  routing heuristic on them (:func:`~.edges.model_edges`);
* :mod:`.model` — the model itself, built in bulk as named column and row blocks
  (:func:`~.model.build_model`), over the cut groups of :mod:`.groups`; :mod:`.result` — the answer (:class:`~.result.RoutingResult`)
  and the restrictions it puts on each history; :mod:`.traps` — the MILP's own trap search;
* :mod:`.solve` — the one front: :func:`~.solve.solve_routing`, its lazy loop over the
  feasibility flows, and the table of backends (:data:`~.solve.SOLVERS`) it picks a solver from,
  the way networkx's ``maximum_flow`` takes a ``flow_func``;
* :mod:`.phases` — what every backend's two phases share (:class:`~.phases.Phase`, the
  heuristic's start, phase 2's objective, the result); :mod:`.certificates` — the walls' cut
  bound as a proof of an answer (:class:`~.certificates.CutProof`);
* :mod:`.bounds` — what is known before a solver runs: the heuristic, the reductions, the
  walls' flow and cut bounds;
* :mod:`.backends` — the solvers: HiGHS (:mod:`.backends.highs`), CP-SAT
  (:mod:`.backends.cpsat_phases`, its child process :mod:`.backends.cpsat`,
  :mod:`.backends.cpsat_worker`, :mod:`.backends.cpsat_pool`), the implicit hitting set that
  CP-SAT's phase 2 may try first (:mod:`.backends.hitting_set`, :mod:`.backends.separator`),
  and the rules that pick a backend on the built model (:mod:`.backends.rules`);
* :mod:`.caps` — the caps on the physical restrictions: their lower bounds and the refusal of a
  cap below them, phase 1's first test within them, and the fewest restrictions a test needs
  where none fits (its package docstring gives its layout);
* :mod:`.solver_control` — time budgets of a running solver, and the stop requests and live
  status it reads from :mod:`.solve_status`;
  :mod:`.restrictions` — an answer as a test strategy.

**The backend contract.** Every backend is one
:class:`~.backends.contract.Backend`: ``session(round)`` opens what holds the model between
the phases (a ``highspy.Highs``, a CP-SAT child), ``phase1(session, round)`` maximises the
flow ``F``, ``phase2(session, round, x, flow, proof)`` minimises the cuts (MILP-agent: the
blocked places first) with ``F`` held, and both return a :class:`~.phases.Phase`: a whole
model solution the backend has checked against the model, its status, gap and what stopped it.
``version()``, ``require()`` and ``figures(session)`` give the package version, a clear error
when the package is missing, and extra stats. Beside the phases a backend may answer
``least(query)`` (:class:`~.backends.contract.LeastQuery`: the least cost over the model's
solutions with flow >= 1, what :func:`~.caps.fewest.fewest_within` asks); HiGHS does, CP-SAT
does not, and :func:`~.solve.solve_least` takes the first backend that does.
``tests/synthesis/test_backend_contract.py`` holds every entry of :data:`~.solve.SOLVERS` to the
same answers.

Reductions, none of which changes the optimum of docs/method.md §5:

* **Pruning.** Nodes of G with no path to ``Tgt`` carry no flow and lie on no
  ``Src -> Tgt`` path, so they (and their edges) are left out of the model; cut
  counts still refer to the whole G.
* **Cut groups.** Edges that must share a cut value (c9 ties over the same
  transition, c14 pairs, fuel levels) share one binary, weighted by the number of
  edges of G it stands for. A group that touches no constraint c5 is never worth
  cutting (cutting only lowers flow and tightens feasibility) and gets no binary.
* **Groups fixed open** (:mod:`synthesis.routing.bounds.reductions`): cut groups no bypass
  walk crosses, groups on every route through I, and (MILP-static) dominated groups get
  upper bound 0, so the solver branches on fewer binaries.
* **Lexicographic objective in two phases.** ``F - (1/|E|) sum d`` with integral F
  is maximised by first maximising F and then minimising the cuts with ``F`` fixed;
  both objectives are integral, so an absolute gap below 1 proves optimality.
* **Integral reachability and flows in MILP-reactive's phase 2** on HiGHS
  (:func:`synthesis.routing.model.phase2_integral_columns`, see :mod:`.backends.highs`).
* **Closing rows per cut column** (large MILP-reactive models on HiGHS,
  :func:`synthesis.routing.backends.rules.per_cut_flow_rows`): the feasibility flows' c7 rows
  written once per history and cut over all the flow edges it closes; the same solutions with
  binary cuts (:func:`synthesis.routing.model._add_feasibility` proves it), a smaller model.
* **Aggregated feasibility flows.** For a history ``q`` with ``K`` kept entry nodes,
  the ``K`` unit flows of c6-c8 are replaced by one flow in which every entry node
  supplies one unit, on edges of capacity ``K (1 - d)``. By flow decomposition each
  unit reaches ``Tgt_sys`` over uncut edges, and conversely ``K`` paths give such a
  flow, so the feasible cut sets are the same. Each flow lives on the part of
  G_sys reachable from its entries and co-reachable to ``Tgt_sys``.

Which histories need their feasibility flows is found by the MILP's own trap search
(:mod:`synthesis.routing.traps`), never by the checks it is held to.

Example::

    >>> from synthesis.problems.load import load_problem
    >>> from synthesis.problems.problem import build_graphs
    >>> from synthesis.routing.options import MilpOptions
    >>> from synthesis.routing.solve import solve_routing
    >>> _, products = build_graphs(load_problem("small-reactive"))
    >>> solve_routing(products, MilpOptions(backend="cpsat", threads=1)).flow
    2
"""
