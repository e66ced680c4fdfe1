"""Explicit-state GR(1) game solver with executable finite-memory strategies.

This package solves *explicit* (enumerated) GR(1) games with integer-indexed
numpy arrays.  It is used by FlowTest wherever a test strategy has to be
synthesised from a finite game graph, and it is written so that games with
~10^5 positions and ~10^6 moves are solved in about a second: every fixpoint
step is a vectorised operation over CSR arrays (sparse matrix-vector
products, ``np.bincount``, ``np.minimum.reduceat``, fancy indexing), and the attractor-like inner
fixpoints are computed with per-choice counters that are updated frontier by
frontier, so no fixpoint contains a per-position Python loop.

Game model and semantics
------------------------
A :class:`~.game.GR1Game` is an alternating game played in *rounds*.  A round starts
at a **position** ``v``:

1. the **environment** picks one of the *choices* ``c`` with
   ``choice_owner[c] == v``;
2. the **system** (the player we synthesise for) picks a successor position
   from ``choice_succ[choice_succ_ptr[c]:choice_succ_ptr[c + 1]]``.

Conventions at dead ends:

* a position without environment choices is *winning for the system* (the
  environment cannot move, i.e. it violated its safety assumption);
* a choice without successors is *losing for the system* (the system cannot
  respond, i.e. it violated its safety guarantee).

Infinite plays are judged at round boundaries (on positions) by the GR(1)
condition ``(AND_i GF J^e_i) -> (AND_j GF J^s_j)``.  An empty list of
environment liveness sets means "no assumption" (``true``); an empty list of
system liveness sets means the single guarantee ``GF true`` (a pure safety
game).  The initial condition is a list of *groups*: the environment picks a
group, then the system picks a position inside it; the game is realizable iff
**every** group contains at least one winning position (an ``forall env
exists sys`` initial condition; an empty list of groups is vacuously
realizable, an empty group is unrealizable).

Algorithm
---------
:func:`~.solver.solve` evaluates the Piterman-Pnueli-Sa'ar triple fixpoint::

    Z = nu Z. AND_j mu Y. OR_i nu X. (J^s_j & cpre(Z)) | cpre(Y) | (!J^e_i & cpre(X))

where ``cpre(S)`` is the set of positions from which, for every environment
choice, the system has a successor in ``S`` (positions without choices
belong to every ``cpre(S)``).  ``nu Z`` is iterated Gauss-Seidel style.  The
inner ``mu Y`` is reached by alternating a cheap *closure* step (the system
attractor of ``Y``, computed layer by layer with incremental counters) and a
*persistence* step (one ``nu X``, computed as the complement of an
environment attractor, per assumption).  Every batch of positions added to
``Y`` receives the next *rank*; ranks and the ``X`` memberships are exactly
the data the strategy needs.

Cost: each closure is linear in the game size; each persistence step is
linear in the part of the game still outside ``Y``.  Random games with
10^5 positions / 10^6 moves take a fraction of a second.  The worst case
(games that need a persistence step for every few positions of a long
chain) is quadratic, as for the textbook algorithm.

Strategy
--------
:class:`~.strategy.GR1Strategy` is the usual counter strategy, tabulated.  Its memory is
the index ``j`` of the guarantee currently pursued (``n_memory`` equals the
number of guarantees; the initial memory is ``0``).  For memory ``j`` at a
position ``v`` of ``Y``-rank ``r`` (for goal ``j``) and every environment
choice ``c`` the table stores the system's answer:

* ``v`` in ``J^s_j & cpre(Z)`` (goal ``j`` is being visited *now*): move into
  ``Z`` (preferring a low rank for goal ``j+1``) and set the memory to
  ``(j + 1) mod n``.  The memory is thus updated in the step that *leaves*
  a reached ``J^s_j`` position: the memory stored with a position is the goal
  that is still pending there;
* ``v`` entered ``Y`` through ``cpre`` of the positions of rank ``< r``:
  move to a position of rank ``< r`` (memory unchanged);
* otherwise ``v`` entered in a persistence step and lies in
  ``!J^e_i & cpre(X_i)`` for the smallest such ``i``: move to a position of
  rank ``< r`` or of rank ``r`` inside ``X_i`` (lower ranks preferred;
  memory unchanged).

With fixed memory the rank never increases and, within a rank, the index
``i`` never increases, so a play that stops cycling through the goals ends
up staying in some ``!J^e_i`` forever, i.e. it violates an assumption.
:func:`~.verify.verify_strategy` checks winning-ness independently by model checking
the closed loop.

Layout, one stage of the algorithm a module
-------------------------------------------
1. :mod:`.game` — the input: :class:`~.game.GR1Game`, the game as validated, read-only arrays
   (the test agent's game of docs/method.md §7 is built as one by
   :func:`synthesis.test_agent.game.build_agent_game`);
2. :mod:`.index` — the game's CSR and reverse-CSR views and the vectorised primitives every
   fixpoint runs on: ``cpre``, the environment attractor that gives ``nu X``, and ``cpre(Y)``
   kept by counters for a growing ``Y``;
3. :mod:`.basin` — the inner ``mu Y`` of one guarantee, with the rank and the persistence
   data of every position;
4. :mod:`.solver` — the outer ``nu Z`` over every guarantee, realizability from the initial
   groups, and the answer (:func:`~.solver.solve`, :class:`~.solver.GR1Result`);
5. :mod:`.extract` — the counter strategy tabulated from the last pass's ranks;
6. :mod:`.strategy` — that table as a value (:class:`~.strategy.GR1Strategy`): its moves, its
   JSON form;
7. :mod:`.verify` — the independent check of a strategy against the game alone
   (:func:`~.verify.verify_strategy`, :class:`~.verify.StrategyError`).

The package imports nothing itself, so a reader of strategies (the test agent's controller)
loads :mod:`.strategy` alone.

Example::

    >>> from synthesis.test_agent.gr1.game import GR1Game
    >>> from synthesis.test_agent.gr1.solver import solve
    >>> from synthesis.test_agent.gr1.verify import verify_strategy
    >>> game = GR1Game.from_lists(2, [(0, [1]), (1, [0])], initial=[[0]], sys_liveness=[[1]])
    >>> result = solve(game)
    >>> result.realizable, result.strategy is not None and verify_strategy(game, result.strategy) is None
    (True, True)
"""
