"""Stage 1 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the input, an explicit
alternating GR(1) game as validated, read-only arrays (:class:`GR1Game`), built from arrays or
from plain Python containers (:meth:`GR1Game.from_lists`)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


def _as_index_array(value: Any, name: str, upper: int | None) -> np.ndarray:
    """Return ``value`` as a read-only 1-D int64 array of indices.

    Parameters
    ----------
    value
        Array-like of integers.
    name
        Field name used in error messages.
    upper
        If given, every entry must lie in ``[0, upper)``.

    Returns
    -------
    numpy.ndarray
        A fresh, read-only int64 array.

    Raises
    ------
    ValueError
        If ``value`` is not a 1-D integer array or has out-of-range entries.
    """
    arr = np.asarray(value)
    if arr.size == 0:
        arr = arr.reshape(-1).astype(np.int64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name} must contain integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64, copy=True)
    if upper is not None and arr.size:
        bad = np.flatnonzero((arr < 0) | (arr >= upper))
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"{name}[{k}] = {int(arr[k])} is out of range [0, {upper})")
    arr.flags.writeable = False
    return arr


def _as_mask(value: Any, name: str, n: int) -> np.ndarray:
    """Return ``value`` as a read-only boolean mask of length ``n``; ``ValueError`` if it is not
    a boolean array of shape ``(n,)``."""
    arr = np.asarray(value)
    if arr.dtype != np.bool_:
        raise ValueError(f"{name} must be a boolean mask over positions, got dtype {arr.dtype}")
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    arr = arr.copy()
    arr.flags.writeable = False
    return arr


def _set_to_mask(value: Any, name: str, n: int) -> np.ndarray:
    """Convert a position set (iterable of indices or bool mask) to a mask; ``ValueError`` if
    an index is out of range or a mask has the wrong length."""
    if isinstance(value, np.ndarray) and value.dtype == np.bool_:
        return _as_mask(value, name, n)
    idx = _as_index_array(list(value), name, n)
    mask = np.zeros(n, dtype=bool)
    mask[idx] = True
    return mask


@dataclass(frozen=True, eq=False)
class GR1Game:
    """An explicit alternating GR(1) game (its rounds and winning condition: :mod:`synthesis.test_agent.gr1`).

    Parameters
    ----------
    n_positions
        Number of positions; positions are ``0 .. n_positions - 1``.  At a
        position the environment chooses next.
    choice_owner
        ``int`` array ``[n_choices]``: the position at which each environment
        choice is available.
    choice_succ_ptr
        CSR pointer ``[n_choices + 1]`` into ``choice_succ``.
    choice_succ
        ``int`` array: the positions the system may move to after each
        choice (choice ``c`` owns ``choice_succ[ptr[c]:ptr[c + 1]]``).
    initial
        Initial groups (``int`` arrays of positions).  For every group
        (picked by the environment) the system must be able to pick a
        winning position inside it.
    env_liveness
        Boolean masks ``J^e_i`` over positions (assumptions ``GF J^e_i``).
    sys_liveness
        Boolean masks ``J^s_j`` over positions (guarantees ``GF J^s_j``); an
        empty list stands for the single guarantee ``GF true``.

    Raises
    ------
    ValueError
        If the arrays are inconsistent (bad shapes, dtypes or indices).

    Notes
    -----
    The arrays are copied and made read-only on construction, so a game is
    immutable and can be shared safely.  Use :meth:`from_lists` to build a
    game from plain Python containers.
    """

    n_positions: int
    choice_owner: np.ndarray
    choice_succ_ptr: np.ndarray
    choice_succ: np.ndarray
    initial: list[np.ndarray]
    env_liveness: list[np.ndarray]
    sys_liveness: list[np.ndarray]

    def __post_init__(self) -> None:
        """Validate and normalise all fields (called by the dataclass)."""
        n = self.n_positions
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)):
            raise ValueError(f"n_positions must be an int, got {n!r}")
        n = int(n)
        if n < 0:
            raise ValueError(f"n_positions must be >= 0, got {n}")
        owner = _as_index_array(self.choice_owner, "choice_owner", n)
        succ = _as_index_array(self.choice_succ, "choice_succ", n)
        ptr = _as_index_array(self.choice_succ_ptr, "choice_succ_ptr", None)
        m = owner.size
        if ptr.size != m + 1:
            raise ValueError(f"choice_succ_ptr must have n_choices + 1 = {m + 1} entries, got {ptr.size}")
        if ptr[0] != 0:
            raise ValueError(f"choice_succ_ptr[0] must be 0, got {int(ptr[0])}")
        if np.any(np.diff(ptr) < 0):
            raise ValueError("choice_succ_ptr must be non-decreasing")
        if ptr[-1] != succ.size:
            raise ValueError(f"choice_succ_ptr[-1] = {int(ptr[-1])} must equal len(choice_succ) = {succ.size}")
        for field_name in ("initial", "env_liveness", "sys_liveness"):
            if isinstance(getattr(self, field_name), (np.ndarray, str, bytes)):
                raise ValueError(f"{field_name} must be a list of arrays")
        initial = [_as_index_array(g, f"initial[{k}]", n) for k, g in enumerate(self.initial)]
        env = [_as_mask(s, f"env_liveness[{k}]", n) for k, s in enumerate(self.env_liveness)]
        sys_ = [_as_mask(s, f"sys_liveness[{k}]", n) for k, s in enumerate(self.sys_liveness)]
        object.__setattr__(self, "n_positions", n)
        object.__setattr__(self, "choice_owner", owner)
        object.__setattr__(self, "choice_succ_ptr", ptr)
        object.__setattr__(self, "choice_succ", succ)
        object.__setattr__(self, "initial", initial)
        object.__setattr__(self, "env_liveness", env)
        object.__setattr__(self, "sys_liveness", sys_)

    @property
    def n_choices(self) -> int:
        """Number of environment choices (over all positions)."""
        return int(self.choice_owner.size)

    @property
    def n_edges(self) -> int:
        """Number of system moves (entries of ``choice_succ``)."""
        return int(self.choice_succ.size)

    def successors(self, choice: int) -> np.ndarray:
        """Return the positions the system may move to after ``choice``."""
        return self.choice_succ[self.choice_succ_ptr[choice] : self.choice_succ_ptr[choice + 1]]

    @classmethod
    def from_lists(
        cls,
        n_positions: int,
        choices: Sequence[tuple[int, Iterable[int]]],
        initial: Iterable[Iterable[int]],
        env_liveness: Iterable[Iterable[int] | np.ndarray] = (),
        sys_liveness: Iterable[Iterable[int] | np.ndarray] = (),
    ) -> GR1Game:
        """Build a game from plain Python containers.

        Parameters
        ----------
        n_positions
            Number of positions.
        choices
            One ``(owner_position, successor_positions)`` pair per environment
            choice; the choice index is the index in this sequence.
        initial
            Initial groups, each an iterable of positions.
        env_liveness, sys_liveness
            Liveness sets, each given either as an iterable of positions or as
            a boolean numpy mask of length ``n_positions``.

        Returns
        -------
        GR1Game
            The validated game.

        Raises
        ------
        ValueError
            If a choice is malformed or any index is out of range.
        """
        if isinstance(n_positions, bool) or not isinstance(n_positions, (int, np.integer)):
            raise ValueError(f"n_positions must be an int, got {n_positions!r}")
        n = int(n_positions)
        if n < 0:
            raise ValueError(f"n_positions must be >= 0, got {n}")
        owners: list[int] = []
        ptr: list[int] = [0]
        succ: list[int] = []
        for k, item in enumerate(choices):
            try:
                owner, targets = item
            except (TypeError, ValueError):
                raise ValueError(f"choices[{k}] must be a pair (owner, successors), got {item!r}") from None
            if isinstance(owner, bool) or not isinstance(owner, (int, np.integer)):
                raise ValueError(f"choices[{k}]: owner must be an int, got {owner!r}")
            if not 0 <= int(owner) < n:
                raise ValueError(f"choices[{k}]: owner {int(owner)} is out of range [0, {n})")
            tlist = [int(t) for t in targets]
            for t in tlist:
                if not 0 <= t < n:
                    raise ValueError(f"choices[{k}]: successor {t} is out of range [0, {n})")
            owners.append(int(owner))
            succ.extend(tlist)
            ptr.append(len(succ))
        groups = [_as_index_array([int(p) for p in g], f"initial[{k}]", n) for k, g in enumerate(initial)]
        env = [_set_to_mask(s, f"env_liveness[{k}]", n) for k, s in enumerate(env_liveness)]
        sys_ = [_set_to_mask(s, f"sys_liveness[{k}]", n) for k, s in enumerate(sys_liveness)]
        return cls(
            n_positions=n,
            choice_owner=np.asarray(owners, dtype=np.int64),
            choice_succ_ptr=np.asarray(ptr, dtype=np.int64),
            choice_succ=np.asarray(succ, dtype=np.int64),
            initial=groups,
            env_liveness=env,
            sys_liveness=sys_,
        )
