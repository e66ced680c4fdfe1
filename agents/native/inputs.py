"""The observation entries a native network reads while it trains (``NativeArgs.inputs``):
every entry (``"all"``), or only those that vary over the train tests' observations and the
memory (``"varying"``, the default).

Why: on a standard pool more than half of a flat observation never changes (on
``reachability1/5x5-v2``: the ``free`` plane, the four wall planes, the test-agent plane and
the doors of the border cells, 170 of 306 entries), and the first layer, which reads every
entry, is most of an MLP's arithmetic. An entry that never changes over the training data
carries nothing a bias does not; the network trains on the others
(:func:`varying_columns`), and is **widened** back (:func:`widen`: zero weights on the
entries it did not read) for evaluation and for the checkpoint, which keeps its format and
reads the full observation: on a test where such an entry does change, the saved network
ignores it, as a network trained on all entries could only guess there.

Example::

    columns = varying_columns(np_env.unwrapped.pool.obs, memory=25)     # int64 indices, or None
    agent = make_agent(len(columns), n_actions, hidden)
    full = widen(agent, columns, obs_size + 25)                          # reads the whole observation
"""

from __future__ import annotations

import numpy as np
import torch

from .agent import Agent
from .networks import make_agent


def varying_columns(table: np.ndarray, memory: int = 0) -> np.ndarray | None:
    """The entries of the observation ``table`` (one row per configuration of the train
    tests, ``[rows, obs_size]``) that are not the same in every row, then the ``memory``
    entries appended after them; ``None`` when every entry varies (nothing to drop).

    Raises
    ------
    ValueError
        For a table that is not two-dimensional or has no row.
    """
    t = np.asarray(table)
    if t.ndim != 2 or t.shape[0] == 0:
        raise ValueError(f"an observation table is [rows, entries] with a row, not shape {t.shape}")
    varies = np.flatnonzero(t.max(axis=0) != t.min(axis=0))
    if varies.size == t.shape[1]:
        return None
    return np.concatenate([varies, np.arange(t.shape[1], t.shape[1] + memory)]).astype(np.int64)


def widen(agent: Agent, columns: torch.Tensor, full_size: int) -> Agent:
    """A network of the same kind that reads all ``full_size`` entries: ``agent``'s weights,
    its input weights (:meth:`Agent.input_weights`) scattered to ``columns`` and zero
    elsewhere; the same outputs as ``agent`` on ``x[:, columns]``."""
    net = agent.settings()
    wide = make_agent(full_size, agent.n_actions, net["hidden"], net["kind"], net["gru_hidden"]).to(columns.device)
    state = {k: v.detach().clone() for k, v in agent.state_dict().items()}
    for name in agent.input_weights():
        w = state[name]
        full = w.new_zeros((w.shape[0], full_size))
        full[:, columns] = w
        state[name] = full
    wide.load_state_dict(state)
    wide.train(agent.training)
    return wide


__all__ = ["varying_columns", "widen"]
