"""The SUT's place memory (:mod:`flowtest_env.memory`) of a batch of runs, in torch: what the
torch env (:mod:`flowtest_env.torch_vector`, ``memory="counts"``) and the native trainer
append to each observation.

Example::

    import torch
    from flowtest_env.torch_memory import BatchPlaceMemory
    memory = BatchPlaceMemory(slice(0, 25), "counts")
    x = memory(obs, start)        # obs: float32[N, n]; start: bool[N], the episodes' first observations

torch is imported here: ``import flowtest_env`` works without it.
"""

from __future__ import annotations

from typing import Any

import torch

from .memory import first_memory, increment_of, remember


class BatchPlaceMemory:
    """The place memory of ``N`` runs: ``where`` is the SUT's position in the observation,
    ``kind`` ``"visited"`` or ``"counts"``. Each call takes one observation per run and the
    runs whose episode starts there (their memory restarts from that observation), and
    returns the observations with the memory appended."""

    def __init__(self, where: slice, kind: str = "visited") -> None:
        self.where, self.kind = where, kind
        self.increment = increment_of(kind)
        self.size = where.stop - where.start
        self.seen: torch.Tensor | None = None

    def reset(self) -> None:
        """Forget every run."""
        self.seen = None

    def peek(self, obs: torch.Tensor) -> torch.Tensor:
        """``obs`` with the memory it would give, the memory itself unchanged (an ended
        episode's last observation, in the same-step autoreset mode)."""
        here = obs[:, self.where].float()
        seen = first_memory(here, self.increment) if self.seen is None else remember(self.seen, here, self.increment)
        return torch.cat([obs.float(), seen], dim=1)

    def __call__(self, obs: torch.Tensor, start: torch.Tensor, rows: torch.Tensor | None = None) -> torch.Tensor:
        """``obs`` with the memory, this observation included, appended; ``start``: the runs
        whose episode starts here; ``rows`` (``bool[N]``): only these runs moved (the
        others' memory stays: a masked reset), ``None``: all."""
        here = obs[:, self.where].float()
        first = first_memory(here, self.increment)
        if self.seen is None or self.seen.shape[0] != obs.shape[0]:
            self.seen = first
        else:
            seen = torch.where(start.unsqueeze(-1), first, remember(self.seen, here, self.increment))
            self.seen = seen if rows is None else torch.where(rows.unsqueeze(-1), seen, self.seen)
        return torch.cat([obs.float(), self.seen], dim=1)


def env_memory(env: Any) -> BatchPlaceMemory | None:
    """The memory the torch twin of the NumPy vector env ``env`` appends itself: a
    :class:`BatchPlaceMemory` for ``memory="counts"``; ``None`` otherwise (the
    ``"visited"`` memory rides in the torch env's tables, packed 64 places to a word)."""
    from .wrappers import shared_position_slice

    env = getattr(env, "unwrapped", env)
    if env.config.memory != "counts":
        return None
    return BatchPlaceMemory(shared_position_slice(env.encoders), "counts")


__all__ = ["BatchPlaceMemory", "env_memory"]
