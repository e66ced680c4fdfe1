"""The solvers of the routing model: HiGHS and OR-Tools CP-SAT (:mod:`.cpsat`, run in a child
process: :mod:`.cpsat_worker`, kept warm by :mod:`.cpsat_pool`), and the implicit hitting set
(:mod:`.hitting_set`, with its separator :mod:`.separator`) that CP-SAT's phase 2 of
MILP-static may try first.

This package imports nothing itself: ``experiments.cli.prestart`` imports
:mod:`.cpsat_pool` alone (the standard library only) before the rest of FlowTest loads."""
