"""The solvers of the routing model, each one :class:`~.contract.Backend` (the contract, see
:mod:`synthesis.routing`): HiGHS (:mod:`.highs`: its phases and the checks of every answer)
and OR-Tools CP-SAT (:mod:`.cpsat_phases`: its phases; :mod:`.cpsat`: the child process that
holds the model, run by :mod:`.cpsat_worker` and kept warm by :mod:`.cpsat_pool`); the implicit
hitting set that CP-SAT's phase 2 of MILP-static may try first (:mod:`.hitting_set`, with its
separator :mod:`.separator`); what every backend's phase 1 starts from (:mod:`.phase1_start`);
and the rules that read the built model to choose a backend (:mod:`.rules`). :data:`synthesis.routing.solve.SOLVERS` is the table of them by name.

This package imports nothing itself: ``experiments.cli.prestart`` imports
:mod:`.cpsat_pool` alone (the standard library only) before the rest of FlowTest loads."""
