"""FlowTest's experiments: the library under the ``flowtest`` command line, the command line
itself, maintainer tools and the lab.

The Python API lives in sub-packages, one job per module: :mod:`experiments.evaluation`
(``evaluate(...)``, ``write_report(...)``: systems under test against tests),
:mod:`experiments.benchmark` (``benchmark(...)``: the benchmark protocol on a test pool) and
:mod:`experiments.training` (``train_native(...)``: PPO systems and testers). The command line
(:mod:`experiments.cli`) parses arguments and calls them. This package imports nothing itself:
the console script imports it first thing, before it starts a solver child.
"""
