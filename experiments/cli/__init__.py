"""The ``flowtest`` command line: the console script, the parser, and one module per command
that parses its arguments, calls the library (:mod:`experiments.evaluation`,
:mod:`experiments.benchmark`, :mod:`experiments.training`, ...) and maps errors to exit codes."""
