"""The routing MILP (method.md §5), its greedy heuristic and the HiGHS runner."""
