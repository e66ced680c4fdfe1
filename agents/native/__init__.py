"""The pieces of FlowTest's native masked PPO trainer, one job per module, as CleanRL
splits its variants: :mod:`~agents.native.args` (the settings), :mod:`~agents.native.envs`
(the env and the visited memory), :mod:`~agents.native.agent` (the network contract),
:mod:`~agents.native.mlp` and :mod:`~agents.native.gru` (the two policies),
:mod:`~agents.native.networks` (the one a setting names), :mod:`~agents.native.core` (the
rollout, the advantages and the update they share), :mod:`~agents.native.plr` (prioritized
level replay), :mod:`~agents.native.evaluation` (greedy evaluation and batched play),
:mod:`~agents.native.logs` (the progress logs) and :mod:`~agents.native.checkpoint` (the
checkpoint written and read back). The loop that ties them together, and the public names,
are in :mod:`agents.native_ppo`.

Importing this package imports none of its modules (so loading a checkpoint,
:mod:`agents.native.checkpoint`, does not load the trainer).
"""
