"""Training systems under test and testers with PPO: the library behind ``flowtest train``,
``flowtest train-tester`` and the baselines of ``flowtest benchmark``.

:func:`train_native` (FlowTest's own batched masked PPO, :mod:`agents.native_ppo`) and
:func:`train` (stable-baselines3) train a system under test against a test or a pool and write
the model, its curve and a summary; :func:`train_tester` trains a tester against a fixed
system. The modules: :mod:`~experiments.training.settings` (both trainers' settings, checked),
:mod:`~experiments.training.system` (training a system), :mod:`~experiments.training.tester`
(training a tester), :mod:`~experiments.training.rl` (the ``rl`` extra and the stable-baselines3
pieces both share). docs/training.md describes the settings.

Example::

    from experiments.training import train_native

    summary = train_native("FlowTest-Maze2-v0", 200_000, "ppo-maze2.zip")
    summary["success_rate"]      # single-env evaluation runs that met the system objective
"""

from __future__ import annotations

from .rl import require_native, require_rl, rl_installed
from .settings import DEFAULTS, NATIVE_DEFAULTS, TRAINERS, native_settings
from .system import success_rate, train, train_native
from .tester import train_tester

__all__ = [
    "DEFAULTS",
    "NATIVE_DEFAULTS",
    "TRAINERS",
    "native_settings",
    "require_native",
    "require_rl",
    "rl_installed",
    "success_rate",
    "train",
    "train_native",
    "train_tester",
]
