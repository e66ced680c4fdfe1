"""Which test of a pool an episode plays: a counter-based draw every backend computes alike.

An env holds a *key* (the seed it was reset with) and an *episode counter* (0 for the
first episode after ``reset(seed=key)``, one more at every later reset or autoreset).
The test of episode ``e`` of a pool of ``n`` tests is a pure function of ``(key, e, n)``::

    GOLDEN = 0x9E3779B97F4A7C15
    mix64(x):                       # splitmix64's finalizer, on 64-bit words (mod 2**64)
        x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9
        x = (x ^ (x >> 27)) * 0x94D049BB133111EB
        return x ^ (x >> 31)
    h = mix64(mix64(key) + (e + 1) * GOLDEN)      # every operation mod 2**64
    test = ((h >> 32) * n) >> 32                   # the high 32 bits, scaled to [0, n)

``key`` is taken mod ``2**64`` (a seed is a non-negative integer; ``key % 2**64``), ``e``
is a non-negative integer below ``2**63`` and ``1 <= n <= 2**31``. The last line is
Lemire's multiply-shift: ``h >> 32 < 2**32`` and ``n <= 2**31``, so the product stays
below ``2**63``: no 64-bit unsigned product is needed there.

**On a backend with only signed int64** (torch): hold every 64-bit word as the int64 with
the same bits (``w - 2**64`` when ``w >= 2**63``). Addition, multiplication and XOR wrap
in two's complement and give the same bits; the only unsigned operation is the logical
right shift, written with the arithmetic shift and a mask::

    srl(x, s) = (x >> s) & ((1 << (64 - s)) - 1)     # x >> s arithmetic in int64
    mix64(x):
        x = (x ^ srl(x, 30)) * -4658895280553007687   # 0xBF58476D1CE4E5B9 as int64
        x = (x ^ srl(x, 27)) * -7723592293110705685   # 0x94D049BB133111EB as int64
        return x ^ srl(x, 31)
    h = mix64(mix64(key) + (e + 1) * -7046029254386353131)   # GOLDEN as int64
    test = (srl(h, 32) * n) >> 32

:func:`mix64_int64` is that recipe over NumPy ``int64`` arrays; the tests check it bit for
bit against :func:`draw_test` (plain Python integers) and :func:`draw_tests` (NumPy
``uint64``).

Who uses it: :class:`~flowtest_env.envs.RandomGridEnv` (key = the seed given at
``reset``; a reset without a seed continues the counter; an env never seeded takes its
key once from ``self.np_random``) and the vector envs of :mod:`flowtest_env.vector` (env
``i`` of ``reset(seed=s)`` has key ``s + i``, as ``SyncVectorEnv`` seeds its envs; a list
gives one seed per env). So a ``SyncVectorEnv`` of single envs and a vector env play the
same tests, episode by episode.

Example::

    >>> from flowtest_env.draws import draw_test, draw_word
    >>> [draw_test(0, e, 8) for e in range(8)]
    [7, 3, 0, 7, 0, 2, 1, 6]
    >>> hex(draw_word(0, 0))  # mix64(0) = 0: splitmix64's first output from state 0
    '0xe220a8397b1dcdaf'
"""

from __future__ import annotations

import numpy as np

MASK64 = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15
"""splitmix64's increment (2**64 over the golden ratio, odd)."""
MIX1 = 0xBF58476D1CE4E5B9
MIX2 = 0x94D049BB133111EB
MAX_TESTS = 1 << 31
"""The largest pool the draw reduces to (so ``(h >> 32) * n < 2**63``)."""


def _signed(w: int) -> int:
    """The int64 with the bits of the 64-bit word ``w``."""
    return w - (1 << 64) if w >= (1 << 63) else w


GOLDEN_I64 = _signed(GOLDEN)
MIX1_I64 = _signed(MIX1)
MIX2_I64 = _signed(MIX2)


def mix64(x: int) -> int:
    """splitmix64's finalizer on a 64-bit word (plain Python integers, mod ``2**64``)."""
    x &= MASK64
    x = ((x ^ (x >> 30)) * MIX1) & MASK64
    x = ((x ^ (x >> 27)) * MIX2) & MASK64
    return x ^ (x >> 31)


def draw_word(key: int, episode: int) -> int:
    """The 64-bit word ``h`` of episode ``episode`` of key ``key`` (module docstring)."""
    return mix64((mix64(key & MASK64) + (episode + 1) * GOLDEN) & MASK64)


def draw_test(key: int, episode: int, n_tests: int) -> int:
    """The test (``0..n_tests-1``) episode ``episode`` of an env with key ``key`` plays.

    >>> 0 <= draw_test(7, 0, 5) < 5
    True
    """
    if not 1 <= n_tests <= MAX_TESTS:
        raise ValueError(f"a pool holds 1 to {MAX_TESTS} tests, not {n_tests}")
    return ((draw_word(key, episode) >> 32) * n_tests) >> 32


def key_of_seed(seed: int) -> np.uint64:
    """A seed (any non-negative integer) as the 64-bit key it stands for."""
    return np.uint64(int(seed) & MASK64)


def _mix64_u64(x: np.ndarray) -> np.ndarray:
    x = (x ^ (x >> np.uint64(30))) * np.uint64(MIX1)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(MIX2)
    out: np.ndarray = x ^ (x >> np.uint64(31))
    return out


def draw_tests(keys: np.ndarray, episodes: np.ndarray, n_tests: int) -> np.ndarray:
    """:func:`draw_test` over arrays: ``keys`` (``uint64``), ``episodes`` (integers >= 0)
    -> ``int64`` test indices, one bulk array operation (``uint64`` arithmetic wraps)."""
    if not 1 <= n_tests <= MAX_TESTS:
        raise ValueError(f"a pool holds 1 to {MAX_TESTS} tests, not {n_tests}")
    k = np.asarray(keys, dtype=np.uint64)
    e = np.asarray(episodes).astype(np.uint64)
    with np.errstate(over="ignore"):
        h = _mix64_u64(_mix64_u64(k) + (e + np.uint64(1)) * np.uint64(GOLDEN))
        out: np.ndarray = (((h >> np.uint64(32)) * np.uint64(n_tests)) >> np.uint64(32)).astype(np.int64)
    return out


def _srl(x: np.ndarray, s: int) -> np.ndarray:
    """Logical right shift of int64 words by arithmetic shift and mask."""
    out: np.ndarray = (x >> np.int64(s)) & np.int64((1 << (64 - s)) - 1)
    return out


def mix64_int64(x: np.ndarray) -> np.ndarray:
    """:func:`mix64` written with signed int64 operations only (the torch recipe)."""
    with np.errstate(over="ignore"):
        x = (x ^ _srl(x, 30)) * np.int64(MIX1_I64)
        x = (x ^ _srl(x, 27)) * np.int64(MIX2_I64)
    out: np.ndarray = x ^ _srl(x, 31)
    return out


def draw_tests_int64(keys: np.ndarray, episodes: np.ndarray, n_tests: int) -> np.ndarray:
    """:func:`draw_tests` with signed int64 operations only (``keys`` as the int64 with the
    key's bits): the exact recipe a torch backend runs."""
    if not 1 <= n_tests <= MAX_TESTS:
        raise ValueError(f"a pool holds 1 to {MAX_TESTS} tests, not {n_tests}")
    k = np.asarray(keys, dtype=np.int64)
    e = np.asarray(episodes, dtype=np.int64)
    with np.errstate(over="ignore"):
        h = mix64_int64(mix64_int64(k) + (e + np.int64(1)) * np.int64(GOLDEN_I64))
    out: np.ndarray = (_srl(h, 32) * np.int64(n_tests)) >> np.int64(32)
    return out


__all__ = ["draw_test", "draw_tests", "draw_tests_int64", "mix64", "mix64_int64", "draw_word", "key_of_seed", "GOLDEN", "MAX_TESTS"]
