"""What is known of the routing model's answer before a solver runs: the greedy heuristic's
test and flow upper bound (:mod:`.heuristic`), the cut groups some optimum leaves open
(:mod:`.reductions`), and MILP-static's walls' flow and cut bounds (:mod:`.flow_bound`,
:mod:`.cut_bound`). Each is a proof or a checked answer, so none changes the optimum."""
