"""The dynamic test agent (method.md §7): game, GR(1) solver, counterexample loop."""
