"""What the environments accept: actions and constructor arguments, checked as Gymnasium
and PettingZoo would, with errors that name the argument.

An action is an integer of the action space: a Python ``int``, a NumPy integer, or a
0-d/1-element integer array. Booleans, floats (even ``1.0``), strings and arrays of
another shape are :class:`gymnasium.error.InvalidAction`: silently truncating ``1.7`` to
``1`` would hide a bug in the system under test.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.error import InvalidAction


def action_index(action: Any, n: int) -> int:
    """The action as an index in ``0..n-1``.

    Raises
    ------
    gymnasium.error.InvalidAction
        If ``action`` is not an integer of ``Discrete(n)``.
    """
    a = action
    if isinstance(a, np.ndarray):
        if a.shape not in ((), (1,)):
            raise InvalidAction(f"action {action!r} has shape {a.shape}; expected one integer of Discrete({n})")
        a = a.reshape(()).item() if a.dtype.kind in "iu" else a.reshape(())[()]
    if isinstance(a, (bool, np.bool_)) or not isinstance(a, (int, np.integer)):
        raise InvalidAction(f"action {action!r} ({type(action).__name__}) is not an integer of Discrete({n})")
    a = int(a)
    if not 0 <= a < n:
        raise InvalidAction(f"action {a} is outside Discrete({n})")
    return a


def positive_int(name: str, value: Any) -> int:
    """``value`` as an ``int >= 1`` (booleans, floats and strings refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, not {value!r}")
    return int(value)


def finite_float(name: str, value: Any) -> float:
    """``value`` as a finite ``float`` (booleans, strings, NaN and infinities refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a finite number, not {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, not {value!r}")
    return v


def one_of(name: str, value: Any, allowed: tuple[Any, ...]) -> Any:
    """``value`` if it is one of ``allowed``."""
    if not isinstance(value, (str, type(None))) or value not in allowed:
        raise ValueError(f"unknown {name} {value!r}; expected one of {', '.join(map(repr, allowed))}")
    return value
