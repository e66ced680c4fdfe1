"""The system under test's memory of its own run, one number per place, appended to a flat
observation: what each kind records and the one update rule every env applies.

A reactive test answers the *history* of the run, which the observation does not show, so
FlowTest offers the SUT a memory of the places it has occupied this episode (env option
``memory``, :class:`~flowtest_env.config.EnvConfig`), read only from its own position in the
observations it has seen (never the hidden test objective):

* ``"visited"``: 1 for a place occupied this episode, else 0;
* ``"counts"``: how often each place was occupied this episode, capped at
  :data:`COUNT_CAP` visits and scaled to ``[0, 1]`` (``min(visits, COUNT_CAP) / COUNT_CAP``).

Why counts: under ``"visited"`` the memory stops changing once both cells of a two-cell
loop are marked, so the observation repeats and a deterministic (greedy) policy that
stepped into the loop never leaves it; every greedy failure of the visited baseline on
``reachability1/5x5-v2`` ended that way. Under ``"counts"`` each pass through the loop
changes the observation (up to the cap), so a deterministic policy can act differently on
the second pass. docs/envs/observations.md shows the layout, docs/training.md the measured
effect.

Both kinds are one rule, ``m <- min(m + x * increment, 1)`` with ``x`` the 0/1 position
entries and ``increment`` 1 (``"visited"``, where it is ``max(m, x)``) or ``1 / COUNT_CAP``
(``"counts"``; a power of two, so every value is exact in float32). The single env
(:class:`~flowtest_env.wrappers.VisitedPlaces`), the NumPy vector env
(:mod:`flowtest_env.vector`), the torch env (:mod:`flowtest_env.torch_memory`) and the
native trainer all apply it, so one policy reads the same numbers from each.

Example::

    >>> import numpy as np
    >>> from flowtest_env.memory import increment_of, first_memory, remember_into
    >>> here = np.array([0.0, 1.0, 0.0], dtype=np.float32)       # the SUT is on place 1
    >>> m = first_memory(here, increment_of("counts"))
    >>> remember_into(m, here, increment_of("counts")); m.tolist()  # a second visit
    [0.0, 0.5, 0.0]
"""

from __future__ import annotations

from typing import Any

import numpy as np

MEMORY_KINDS = ("none", "visited", "counts")
"""What a system under test may remember of its own run: nothing, the places it has
occupied, or how often it occupied each (capped at :data:`COUNT_CAP`)."""

PLACE_MEMORIES = ("visited", "counts")
"""The memory kinds that append one entry per place to the observation."""

COUNT_CAP = 4
"""Visits of one place a ``"counts"`` memory tells apart (1, 2, 3, 4 or more: entries
0.25, 0.5, 0.75, 1.0). A power of two: the scaled counts are exact in float32."""

MEANINGS = {
    "visited": "places the SUT has occupied this episode (memory='visited')",
    "counts": f"how often the SUT occupied each place this episode, min(visits, {COUNT_CAP}) / {COUNT_CAP} (memory='counts')",
}
"""What the memory's entries mean, per kind (the observation layout's segment text)."""


def increment_of(kind: str) -> float:
    """What one visit adds to a place's entry: 1 for ``"visited"``, ``1 / COUNT_CAP`` for
    ``"counts"``.

    Raises
    ------
    ValueError
        For ``"none"`` or an unknown kind.
    """
    if kind == "visited":
        return 1.0
    if kind == "counts":
        return 1.0 / COUNT_CAP
    raise ValueError(f"memory {kind!r} keeps no places; expected one of {', '.join(PLACE_MEMORIES)}")


def first_memory(here: Any, increment: float) -> Any:
    """The memory at an episode's first observation (``here``: its 0/1 position entries,
    a NumPy array or a torch tensor): the start place visited once."""
    return here * increment if increment != 1.0 else here.copy() if isinstance(here, np.ndarray) else here.clone()


def remember(seen: Any, here: Any, increment: float) -> Any:
    """The memory after one more observation, as a new array (NumPy or torch): ``seen`` with
    the place of ``here`` (0/1 position entries) visited once more, capped at 1."""
    return (seen + here * increment).clip(max=1.0)


def remember_into(seen: np.ndarray, here: np.ndarray, increment: float) -> None:
    """:func:`remember` in place on NumPy arrays (``seen`` float32, updated)."""
    if increment == 1.0:
        np.maximum(seen, here, out=seen)
        return
    seen += here * np.float32(increment)
    np.minimum(seen, np.float32(1.0), out=seen)


class PlaceMemory:
    """The memory of one run, appended to a flat observation (NumPy): call :meth:`reset` at
    the start of each episode and :meth:`__call__` on every observation, in order. It reads
    only the SUT's own position (``where`` in the observation)."""

    def __init__(self, where: slice, kind: str = "visited") -> None:
        self.where, self.kind = where, kind
        self.increment = increment_of(kind)
        self.size = where.stop - where.start
        self._seen: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the run (the next observation is an episode's first)."""
        self._seen = None

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` (float32) with the memory, this observation included, appended."""
        obs = np.asarray(obs, dtype=np.float32)
        here = obs[self.where]
        if self._seen is None:
            self._seen = first_memory(here, self.increment)
        else:
            remember_into(self._seen, here, self.increment)
        return np.concatenate([obs, self._seen])


__all__ = ["COUNT_CAP", "MEANINGS", "MEMORY_KINDS", "PLACE_MEMORIES", "PlaceMemory", "first_memory", "increment_of", "remember", "remember_into"]
