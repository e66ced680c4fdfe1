"""Stage 6 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the tabulated
finite-memory strategy (:class:`GR1Strategy`) as a value: its moves, and its JSON form
(:meth:`GR1Strategy.to_dict`, :meth:`GR1Strategy.from_dict`), read by the test agent's
controller without the solver."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

_FORMAT = "flowtest.gr1.strategy"
_FORMAT_VERSION = 1


@dataclass
class GR1Strategy:
    """A tabulated finite-memory strategy for the system.

    Parameters
    ----------
    n_positions
        Number of positions of the game the strategy was built for.
    initial
        ``int32`` array ``[n_groups]``: the system's pick in each initial group.
    next_position
        ``int32`` array ``[n_memory, n_choices]``: the successor chosen for
        each (memory, environment choice); ``-1`` where no move is defined
        (the position is losing or the entry is unreachable).
    next_memory
        ``int32`` array ``[n_memory, n_choices]``: the memory after that move
        (``-1`` where ``next_position`` is ``-1``).

    Notes
    -----
    The memory is the index of the guarantee currently pursued; the initial
    memory is :attr:`initial_memory` (``0``).  The memory changes from ``j``
    to ``(j + 1) mod n_memory`` exactly in the move that leaves a position of
    ``J^s_j`` reached while pursuing ``j`` (see :mod:`synthesis.test_agent.gr1`).  A
    run is executed as::

        pos, mem = strategy.initial_choice(g), strategy.initial_memory
        while True:
            c = <environment picks a choice owned by pos>
            pos, mem = strategy.move(mem, c)
    """

    n_positions: int
    initial: np.ndarray
    next_position: np.ndarray
    next_memory: np.ndarray

    initial_memory: int = 0

    def __post_init__(self) -> None:
        """Validate table shapes and value ranges.

        Raises
        ------
        ValueError
            If the arrays are inconsistent.
        """
        self.n_positions = int(self.n_positions)
        self.initial = np.asarray(self.initial, dtype=np.int32).reshape(-1)
        self.next_position = np.asarray(self.next_position, dtype=np.int32)
        self.next_memory = np.asarray(self.next_memory, dtype=np.int32)
        if self.next_position.ndim != 2 or self.next_position.shape != self.next_memory.shape:
            raise ValueError(f"next_position and next_memory must be 2-D arrays of equal shape, got {self.next_position.shape} and {self.next_memory.shape}")
        if self.next_position.shape[0] < 1:
            raise ValueError("a strategy needs at least one memory value")
        if np.any(self.initial < 0) or np.any(self.initial >= self.n_positions):
            raise ValueError("initial positions out of range")
        if np.any(self.next_position < -1) or np.any(self.next_position >= self.n_positions):
            raise ValueError("next_position entries out of range")
        if np.any(self.next_memory < -1) or np.any(self.next_memory >= self.n_memory):
            raise ValueError("next_memory entries out of range")
        if np.any((self.next_position < 0) != (self.next_memory < 0)):
            raise ValueError("next_position and next_memory must be -1 at the same entries")
        if not 0 <= self.initial_memory < self.n_memory:
            raise ValueError("initial_memory out of range")

    @property
    def n_memory(self) -> int:
        """Number of memory values (= number of guarantees)."""
        return int(self.next_position.shape[0])

    @property
    def n_choices(self) -> int:
        """Number of environment choices of the game."""
        return int(self.next_position.shape[1])

    @property
    def table(self) -> dict[str, np.ndarray]:
        """The move table as ``{"next_position": ..., "next_memory": ...}``."""
        return {"next_position": self.next_position, "next_memory": self.next_memory}

    def initial_positions(self) -> np.ndarray:
        """Return the system's pick for every initial group (a copy)."""
        return self.initial.copy()

    def initial_choice(self, group_index: int) -> int:
        """Return the system's (winning) pick in initial group ``group_index``."""
        return int(self.initial[group_index])

    def move(self, memory: int, choice: int) -> tuple[int, int]:
        """Answer an environment choice.

        Parameters
        ----------
        memory
            Current memory value.
        choice
            The environment's choice (owned by the current position).

        Returns
        -------
        tuple[int, int]
            ``(next_position, next_memory)``.

        Raises
        ------
        ValueError
            If the table has no move for this pair (losing or unreachable).
        """
        pos = int(self.next_position[memory, choice])
        if pos < 0:
            raise ValueError(f"no move defined for memory {memory}, choice {choice}")
        return pos, int(self.next_memory[memory, choice])

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable representation (plain lists and ints)."""
        return {
            "format": _FORMAT,
            "version": _FORMAT_VERSION,
            "n_positions": self.n_positions,
            "n_memory": self.n_memory,
            "n_choices": self.n_choices,
            "initial_memory": int(self.initial_memory),
            "initial": self.initial.tolist(),
            "next_position": self.next_position.tolist(),
            "next_memory": self.next_memory.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GR1Strategy:
        """Rebuild a strategy written by :meth:`to_dict`.

        Raises
        ------
        ValueError
            If the format tag, version or table shapes do not match.
        """
        if data.get("format") != _FORMAT or data.get("version") != _FORMAT_VERSION:
            raise ValueError(f"not a {_FORMAT} v{_FORMAT_VERSION} document: format={data.get('format')!r}, version={data.get('version')!r}")
        shape = (int(data["n_memory"]), int(data["n_choices"]))
        nxt = np.asarray(data["next_position"], dtype=np.int32).reshape(shape)
        mem = np.asarray(data["next_memory"], dtype=np.int32).reshape(shape)
        return cls(
            n_positions=int(data["n_positions"]),
            initial=np.asarray(data["initial"], dtype=np.int32),
            next_position=nxt,
            next_memory=mem,
            initial_memory=int(data["initial_memory"]),
        )
