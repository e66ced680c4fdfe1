"""Wrappers for FlowTest environments."""

from __future__ import annotations

from typing import Any, Protocol, SupportsFloat, runtime_checkable

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .config import MEMORY_KINDS as MEMORY_KINDS  # re-exported: the memory kinds live with the options
from .encoding import Encoder, ObservationLayout
from .game import RunState, TestGame
from .memory import PlaceMemory
from .system_product import INF, SystemProduct


@runtime_checkable
class PlaysTestGame(Protocol):
    """What the wrappers read of an unwrapped FlowTest env (:class:`~flowtest_env.envs.FlowTestEnv`):
    its game, the current run and the legal-action mask."""

    game: TestGame
    run: RunState | None

    def action_masks(self) -> np.ndarray: ...


def _flowtest_env(env: gym.Env[np.ndarray, np.int64]) -> PlaysTestGame:
    """The unwrapped FlowTest env behind ``env``.

    Raises
    ------
    TypeError
        If ``env`` does not wrap a FlowTest env.
    """
    inner = env.unwrapped
    if not isinstance(inner, PlaysTestGame):
        raise TypeError(f"{type(inner).__name__} is not a FlowTest env (no game, run and action_masks)")
    return inner


class ActionMaskObservation(gym.Wrapper[dict[str, np.ndarray], np.int64, np.ndarray, np.int64], gym.utils.RecordConstructorArgs):
    """Put the legal-action mask into the observation.

    The observation becomes a ``Dict`` with ``"observation"`` (the wrapped env's
    observation) and ``"action_mask"`` (``int8[n_actions]``, 1 = legal now), the shape
    PettingZoo and most masked-policy libraries expect. The mask is taken from
    ``info["action_mask"]``, which every FlowTest env returns at reset and each step.

    Raises
    ------
    TypeError
        If the wrapped env's action space is not ``Discrete``.
    """

    def __init__(self, env: gym.Env[np.ndarray, np.int64]) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)  # so gymnasium.make(env.spec) rebuilds it
        # gymnasium's annotations type Wrapper.__init__'s env (and Wrapper.env) with the wrapper's own
        # observation type instead of the wrapped env's; `_inner` keeps the wrapped env's types
        super().__init__(env)  # type: ignore[arg-type]
        self._inner = env
        if not isinstance(env.action_space, spaces.Discrete):
            raise TypeError(f"ActionMaskObservation needs a Discrete action space, not {env.action_space}")
        n = int(env.action_space.n)
        # gymnasium's annotations type spaces.Dict as a Space of dicts of spaces, not of samples
        self.observation_space = spaces.Dict(  # type: ignore[assignment]
            {"observation": env.observation_space, "action_mask": spaces.Box(0, 1, shape=(n,), dtype=np.int8)}
        )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self._inner.reset(seed=seed, options=options)
        return {"observation": obs, "action_mask": np.asarray(info["action_mask"], dtype=np.int8)}, info

    def step(self, action: np.int64) -> tuple[dict[str, np.ndarray], SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self._inner.step(action)
        return {"observation": obs, "action_mask": np.asarray(info["action_mask"], dtype=np.int8)}, reward, terminated, truncated, info


# ---------------------------------------------------------------- the SUT's memory


def encoder_of(env: object) -> Encoder:
    """The observation encoder behind a FlowTest env (Gymnasium or PettingZoo, wrapped or not).

    Raises
    ------
    TypeError
        If ``env`` is not a FlowTest env.
    """
    obj, seen = env, 0
    while obj is not None and seen < 16:
        enc = getattr(obj, "encoder", None)
        if isinstance(enc, Encoder):
            return enc
        obj = getattr(obj, "env", None) or getattr(obj, "aec_env", None)
        seen += 1
    enc = getattr(getattr(env, "unwrapped", None), "encoder", None)
    if not isinstance(enc, Encoder):
        raise TypeError(f"{type(env).__name__} exposes no FlowTest observation encoder")
    return enc


def observation_layout(env: object) -> ObservationLayout:
    """Which entries of a FlowTest observation are which: the named segments (planes, the
    restricted-now bits, fuel, objective progress, the visited-places memory) of a flat,
    padded or grid observation, and which segment holds the SUT's own position.

    ``env`` is a FlowTest env (single, vector or PettingZoo; wrapped or not, a
    :class:`VisitedPlaces` wrapper adds its memory; under :class:`ActionMaskObservation`
    the layout is that of ``obs["observation"]``) or an encoder. docs/envs/observations.md
    explains the layouts.

    Example::

        >>> import gymnasium as gym, flowtest_env
        >>> env = gym.make("FlowTest-Maze2-v0", memory="visited")
        >>> obs, info = env.reset(seed=0)
        >>> lay = flowtest_env.observation_layout(env)
        >>> pos = lay[lay.position].of(obs)          # the SUT's cell as a 5x5 one-hot plane
        >>> [int(v) for v in divmod(int(pos.argmax()), 5)] == info["system_state"]
        True

    Raises
    ------
    TypeError
        If ``env`` is not a FlowTest env.
    """
    memory, kind = 0, "visited"
    obj, seen = env, 0
    while obj is not None and seen < 32:
        if isinstance(obj, Encoder):
            lay = obj.layout()
            break
        if isinstance(obj, VisitedPlaces):
            memory += obj.memory.size
            kind = obj.memory.kind
        method = getattr(type(obj), "observation_layout", None)
        if callable(method):
            lay = method(obj)
            break
        obj = getattr(obj, "env", None) or getattr(obj, "aec_env", None)
        seen += 1
    else:
        lay = encoder_of(env).layout()
    return lay.with_memory(memory, kind) if memory else lay


def position_slice(encoder: Encoder) -> slice:
    """Where a flat FlowTest observation holds the one-hot of the SUT's own place: the
    ``system`` plane on grids, the first block on graphs (:mod:`flowtest_env.encoding`).

    Raises
    ------
    ValueError
        For an image-like (``obs_kind="grid"``) observation.
    """
    if encoder.obs_kind == "grid":
        raise ValueError("the visited-places memory needs a flat observation, not obs_kind='grid'")
    return encoder.position_slice()


def shared_position_slice(encoders: list[Encoder]) -> slice:
    """The position slice (:func:`position_slice`) of every encoder of a pool, which must
    be the same for one memory to read them all.

    Raises
    ------
    ValueError
        For image-like observations, or tests whose observations put the SUT's place at
        different entries (mix ``obs_kind="padded"`` for such a pool).
    """
    where = {(sl.start, sl.stop) for sl in (position_slice(e) for e in encoders)}
    if len(where) != 1:
        raise ValueError(
            "a place memory (memory='visited' or 'counts') needs the pool's tests to show the SUT's place at the same entries; "
            "these differ (use obs_kind='padded')"
        )
    start, stop = where.pop()
    return slice(start, stop)


class VisitedMemory(PlaceMemory):
    """The places the SUT has occupied this episode, as a 0/1 vector appended to a flat
    observation (:class:`~flowtest_env.memory.PlaceMemory` of kind ``"visited"``). Call
    :meth:`reset` at the start of each episode and :meth:`__call__` on every observation,
    in order. It reads only the SUT's own position from observations it has seen: never
    the hidden test objective or the test's history."""

    def __init__(self, where: slice) -> None:
        super().__init__(where, "visited")


class VisitedPlaces(gym.ObservationWrapper[np.ndarray, np.int64, np.ndarray], gym.utils.RecordConstructorArgs):
    """Append the places the SUT has occupied this episode to a flat FlowTest observation
    (``memory="counts"``: how often it occupied each, capped; :mod:`flowtest_env.memory`).

    **Why.** A reactive test answers the *history* of the run, which the observation
    does not show (the test objective stays hidden), so the observation alone is not
    Markov for the SUT: on ``FlowTest-Maze2-v0`` the SUT must pass some cells twice and
    act differently the second time, and no policy of the observation alone does (a
    plain MaskablePPO never learns it). With this memory it learns the test
    (docs/benchmarks.md). Same as the env option ``memory="visited"`` (or ``"counts"``).
    Under ``"visited"`` the observation repeats once a loop's places are all marked, so a
    deterministic policy that steps into a loop stays in it; ``"counts"`` changes it on every
    pass, up to :data:`~flowtest_env.memory.COUNT_CAP` visits, so such a policy can leave.

    Usable with any library: ``VisitedPlaces(gymnasium.make("FlowTest-Maze2-v0"))``.
    Masks (``action_masks()``, ``info["action_mask"]``) pass through unchanged.

    Raises
    ------
    ValueError
        If the observation is not flat.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import flowtest_env
    >>> from flowtest_env.wrappers import VisitedPlaces
    >>> env = VisitedPlaces(gym.make("FlowTest-Maze2-v0"))    # 25 more entries: one per cell of the 5x5 maze
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_masks().tolist()
    ((331,), [True, False, True, False, True])
    >>> visited = flowtest_env.observation_layout(env)["visited"]
    >>> visited.start, visited.stop, visited.of(obs).nonzero()     # the SUT's start cell, row 4, column 0
    (306, 331, (array([4]), array([0])))
    """

    def __init__(self, env: gym.Env[np.ndarray, np.int64], memory: str = "visited") -> None:
        gym.utils.RecordConstructorArgs.__init__(self, memory=memory)  # so gymnasium.make(env.spec) rebuilds it
        super().__init__(env)
        self.memory = PlaceMemory(position_slice(encoder_of(env)), memory)
        shape = env.observation_space.shape
        if shape is None or len(shape) != 1:
            raise ValueError(f"the visited-places memory needs a flat observation, not shape {shape}")
        n = int(shape[0]) + self.memory.size
        self.observation_space = spaces.Box(0.0, 1.0, shape=(n,), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.memory.reset()
        return super().reset(seed=seed, options=options)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return self.memory(observation)

    def action_masks(self) -> np.ndarray:
        """The wrapped env's legal actions (sb3-contrib's MaskablePPO convention)."""
        return _flowtest_env(self.env).action_masks()


# ---------------------------------------------------------------- reward shaping


class DistancePotential:
    """``phi = -min(d, 4 scale) / scale``: ``d`` the number of steps from the SUT's state to
    its objective on its own product graph ``G_sys`` past the static walls
    (:class:`~flowtest_env.system_product.SystemProduct`); ``-4`` where it is unreachable.
    It uses only what the SUT knows (its map and its objective), never the test objective."""

    def __init__(self, scale: float) -> None:
        if scale <= 0:
            raise ValueError(f"the shaping scale must be positive, not {scale}")
        self.scale = float(scale)
        self._products: dict[int, SystemProduct] = {}

    def __call__(self, game: TestGame, run: RunState) -> float:
        prod = self._products.get(id(game))
        if prod is None:
            prod = self._products[id(game)] = SystemProduct(game)
        q = int(game.q_sys[run.history])
        d = prod.distances()[prod.node(run.system, q)]
        return -min(float(d), 4 * self.scale) / self.scale if d < INF else -4.0


class DistanceShaping(gym.Wrapper[np.ndarray, np.int64, np.ndarray, np.int64], gym.utils.RecordConstructorArgs):
    """Potential-based reward shaping (Ng et al. 1999, keeps the optimal policies):
    ``r + gamma * phi(s') - phi(s)`` with :class:`DistancePotential` (``phi = 0`` at the
    end of an episode). Off unless asked for: the same as the env option
    ``shaping=scale`` (with ``shaping_gamma``). Set ``gamma`` to the learner's discount.

    Why: the mazes' sparse goal reward is rarely found by random exploration; the
    potential rewards progress towards the SUT's *own* objective only.
    """

    def __init__(self, env: gym.Env[np.ndarray, np.int64], scale: float = 10.0, gamma: float = 0.99) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, scale=scale, gamma=gamma)  # gymnasium.make(env.spec) rebuilds it
        super().__init__(env)
        self.potential = DistancePotential(scale)
        self.gamma = float(gamma)
        self._last = 0.0

    def _phi(self) -> float:
        u = _flowtest_env(self.env)
        if u.run is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        return self.potential(u.game, u.run)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        out = self.env.reset(seed=seed, options=options)
        self._last = self._phi()
        return out

    def step(self, action: np.int64) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, r, term, trunc, info = self.env.step(action)
        phi = 0.0 if term else self._phi()
        r = float(r) + self.gamma * phi - self._last
        self._last = phi
        return obs, r, term, trunc, info

    def action_masks(self) -> np.ndarray:
        """The wrapped env's legal actions (sb3-contrib's MaskablePPO convention)."""
        return _flowtest_env(self.env).action_masks()
