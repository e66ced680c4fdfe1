"""One frozen configuration for every FlowTest environment, checked by one validator.

:class:`EnvConfig` holds the options a FlowTest env takes besides its test: which
restrictions are shown, the step budget, the observation, rendering, the reward weights,
the SUT's memory and reward shaping. The single env (:class:`~flowtest_env.envs.FlowTestEnv`,
:class:`~flowtest_env.envs.RandomGridEnv`), the NumPy vector envs
(:mod:`flowtest_env.vector`) and the PettingZoo env build one from their keyword
arguments, so an option means the same, and is refused with the same message, whichever
env takes it::

    >>> from flowtest_env.config import EnvConfig
    >>> EnvConfig(memory="visited", shaping=10.0).memory
    'visited'
    >>> EnvConfig(max_steps=2.7)
    Traceback (most recent call last):
    ...
    ValueError: max_steps must be a positive integer, not 2.7

Every env takes its options the same way, through :func:`config_from`: as keyword arguments
(``gym.make("FlowTest-Maze2-v0", max_steps=50)``) or as one ``config=EnvConfig(...)``, and
exposes the checked object as ``env.config``. No env restates the option list: the
constructors take ``config=None, **options`` and :func:`with_option_signature` gives them
the options' signature for ``help()`` and ``inspect.signature``::

    >>> import inspect
    >>> from flowtest_env.envs import FlowTestEnv
    >>> inspect.signature(FlowTestEnv).parameters["max_steps"].default is None
    True

An env that supports only part of an option's values (the vector env: ``rgb_array``
rendering only) refuses the rest after this check, naming the option. The two-player
PettingZoo env (:mod:`flowtest_env.multiagent`) applies the options of the game and the
picture and the system's rewards, and refuses a value other than the default for the
options of the single-agent learner it has no use for (:data:`MULTIAGENT_UNUSED`), after
checking it with the same validator.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from .encoding import OBS_KINDS
from .memory import MEMORY_KINDS as MEMORY_KINDS  # re-exported: what a SUT may remember (flowtest_env.memory)
from .validation import finite_float, one_of, positive_int

SETTINGS: tuple[None, str, str] = (None, "instantaneous", "accumulative")
"""``setting``: the test's own (``None``), or which restrictions are shown."""
VIEWS = ("system", "engineer")
"""``view``: what a picture shows (``"engineer"`` adds the hidden test cells)."""
RENDER_MODES: tuple[None, str, str, str] = (None, "rgb_array", "ansi", "human")
"""``render_mode`` values some FlowTest env takes (each env's ``metadata`` lists its own)."""


@dataclass(frozen=True)
class EnvConfig:
    """The options of a FlowTest env (every field checked when the object is made).

    Attributes
    ----------
    setting
        ``None`` (the test's own), ``"instantaneous"`` (restrictions on the current
        state shown) or ``"accumulative"`` (every restriction met under the history).
    max_steps
        The step budget (a positive integer), ``None``: the test's default.
    obs_kind
        ``"flat"``, ``"grid"`` or ``"padded"`` (:mod:`flowtest_env.encoding`).
    pad_to
        The grid side of ``"padded"`` observations.
    render_mode
        ``None``, ``"rgb_array"``, ``"ansi"`` or ``"human"`` (a window; needs pygame).
    view
        ``"system"`` or ``"engineer"``.
    tile_size
        Pixels per grid cell in pictures.
    step_cost, restricted_penalty, goal_reward, violation_penalty
        The reward weights (finite numbers).
    memory
        ``"none"``, ``"visited"`` (the places the SUT has occupied this episode, appended
        to a flat observation) or ``"counts"`` (how often it occupied each, capped at
        :data:`~flowtest_env.memory.COUNT_CAP` visits and scaled to ``[0, 1]``; a
        deterministic policy can leave a loop under it: :mod:`flowtest_env.memory`).
    shaping
        ``0`` (off) or the scale of potential-based shaping towards the SUT's objective.
    shaping_gamma
        The shaping's discount, in ``[0, 1]``.
    numeric_infos
        ``False``: ``info["system_state"]`` is the state as JSON data (``[row, col]``,
        ``[[row, col], fuel]`` or a name) and ``info["verdict"]["system_objective"]`` a
        word; ``True``: numbers only, for libraries that turn infos into tensors (TorchRL):
        the SUT's state index (``env.game.state_json(i)`` names it) and the outcome code
        (0 open, 1 met, 2 violated: :data:`flowtest_env.compiled.OUTCOMES`).

    Raises
    ------
    ValueError
        On any value outside the above (booleans, strings or ``2.7`` for an integer,
        NaN or infinities for a number).

    Examples
    --------
    >>> from flowtest_env import EnvConfig, make_env
    >>> config = EnvConfig(max_steps=20, memory="visited")
    >>> env = make_env("small-reactive", config=config)      # or make_env("small-reactive", max_steps=20, ...)
    >>> env.config.max_steps, env.config.memory, env.observation_space.shape
    (20, 'visited', (84,))
    >>> EnvConfig(max_steps=0)
    Traceback (most recent call last):
    ...
    ValueError: max_steps must be a positive integer, not 0
    """

    setting: str | None = None
    max_steps: int | None = None
    obs_kind: str = "flat"
    pad_to: int = 8
    render_mode: str | None = None
    view: str = "system"
    tile_size: int = 32
    step_cost: float = 0.01
    restricted_penalty: float = 0.05
    goal_reward: float = 1.0
    violation_penalty: float = 1.0
    memory: str = "none"
    shaping: float = 0.0
    shaping_gamma: float = 0.99
    numeric_infos: bool = False

    def __post_init__(self) -> None:
        checked = validate(self)
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, checked[f.name])

    def replace(self, **changes: Any) -> EnvConfig:
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    def kwargs(self) -> dict[str, Any]:
        """The fields as keyword arguments."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def with_max_steps(self, default: int) -> EnvConfig:
        """This configuration with ``default`` as the step budget if none was given."""
        return self if self.max_steps is not None else self.replace(max_steps=default)


FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(EnvConfig))
"""The option names of :class:`EnvConfig`, in order."""


def validate(config: EnvConfig) -> dict[str, Any]:
    """The checked, normalised values of ``config``'s fields (the one validator).

    Raises
    ------
    ValueError
        Naming the first option with a value it does not take.
    """
    c = config
    one_of("setting", c.setting, SETTINGS)
    max_steps = None if c.max_steps is None else positive_int("max_steps", c.max_steps)
    one_of("obs_kind", c.obs_kind, OBS_KINDS)
    pad_to = positive_int("pad_to", c.pad_to)
    one_of("render_mode", c.render_mode, RENDER_MODES)
    one_of("view", c.view, VIEWS)
    tile_size = positive_int("tile_size", c.tile_size)
    weights = {k: finite_float(k, getattr(c, k)) for k in ("step_cost", "restricted_penalty", "goal_reward", "violation_penalty")}
    one_of("memory", c.memory, MEMORY_KINDS)
    if c.memory != "none" and c.obs_kind == "grid":
        raise ValueError(f"memory={c.memory!r} needs a flat observation (obs_kind='flat' or 'padded'), not obs_kind='grid'")
    shaping = finite_float("shaping", c.shaping)
    if shaping < 0:
        raise ValueError(f"shaping must be 0 (off) or a positive scale, not {c.shaping!r}")
    gamma = finite_float("shaping_gamma", c.shaping_gamma)
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"shaping_gamma must be a discount in [0, 1], not {c.shaping_gamma!r}")
    if not isinstance(c.numeric_infos, (bool, np.bool_)):
        raise ValueError(f"numeric_infos must be True or False, not {c.numeric_infos!r}")
    return {
        "numeric_infos": bool(c.numeric_infos),
        "setting": c.setting,
        "max_steps": max_steps,
        "obs_kind": c.obs_kind,
        "pad_to": pad_to,
        "render_mode": c.render_mode,
        "view": c.view,
        "tile_size": tile_size,
        **weights,
        "memory": c.memory,
        "shaping": shaping,
        "shaping_gamma": gamma,
    }


MULTIAGENT_UNUSED: tuple[str, ...] = ("memory", "shaping", "shaping_gamma", "numeric_infos")
"""The options the two-player env has no use for: the learner's memory and reward shaping
(single-agent wrappers of the system's observation and reward) and ``numeric_infos`` (the
two-player env's own ``info_kind="numeric"`` does that job for both players)."""

DEFAULTS: dict[str, Any] = {f.name: f.default for f in dataclasses.fields(EnvConfig)}
"""Each option's default value."""


def config_from(who: str, config: EnvConfig | None, options: Mapping[str, Any], defaults: Mapping[str, Any] | None = None) -> EnvConfig:
    """The options of the env ``who``, given as ``config=`` or as keyword arguments (not both).

    ``defaults`` are the env's own defaults where they differ from :class:`EnvConfig`'s
    (the two-player env shows the engineer's view); they apply to keyword arguments only,
    a ``config`` is taken as it is.

    Raises
    ------
    TypeError
        On a keyword argument that is no option, on options given both ways, or on a
        ``config`` that is not an :class:`EnvConfig`.
    ValueError
        On an option's value (:func:`validate`).

    Example::

        >>> config_from("FlowTestEnv", None, {"max_steps": 9}).max_steps
        9
        >>> config_from("raw_env", None, {}, defaults={"view": "engineer"}).view
        'engineer'
    """
    if config is not None:
        if options:
            raise TypeError(f"{who}: pass the env options either as config= or as keyword arguments, not both")
        if not isinstance(config, EnvConfig):
            raise TypeError(f"{who}: config must be an EnvConfig, not {type(config).__name__}")
        return config
    unknown = sorted(k for k in options if k not in FIELDS)
    if unknown:
        raise TypeError(f"{who} got unexpected keyword arguments: {', '.join(unknown)}")
    return EnvConfig(**{**(defaults or {}), **options})


def refuse_unused(who: str, config: EnvConfig, unused: tuple[str, ...], why: str) -> None:
    """Refuse a value other than the default for the options ``who`` has no use for (the
    value itself has passed :func:`validate` already).

    Raises
    ------
    ValueError
        Naming the first such option and ``why``.
    """
    for name in unused:
        if getattr(config, name) != DEFAULTS[name]:
            raise ValueError(f"{who} does not take {name}={getattr(config, name)!r} ({why}); leave it at its default {DEFAULTS[name]!r}")


C = TypeVar("C", bound=type)


def with_option_signature(exclude: tuple[str, ...] = (), **defaults: Any) -> Callable[[C], C]:
    """A class decorator: the class's ``__init__(..., config=None, **options)`` shows the
    options of :class:`EnvConfig` (less ``exclude``, with the env's own ``defaults``) as
    keyword-only parameters in ``help()`` and :func:`inspect.signature`, so the option list
    is written once, here, and still read at each env."""

    def decorate(cls: C) -> C:
        init = cls.__init__  # type: ignore[misc]
        sig = inspect.signature(init)
        params = [p for p in sig.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
        taken = {p.name for p in params}
        hints = {f.name: f.type for f in dataclasses.fields(EnvConfig)}
        params += [
            inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=defaults.get(name, DEFAULTS[name]), annotation=hints[name])
            for name in FIELDS
            if name not in exclude and name not in taken
        ]
        init.__signature__ = sig.replace(parameters=params)
        return cls

    return decorate


__all__ = [
    "DEFAULTS",
    "EnvConfig",
    "FIELDS",
    "MEMORY_KINDS",
    "MULTIAGENT_UNUSED",
    "RENDER_MODES",
    "SETTINGS",
    "VIEWS",
    "config_from",
    "refuse_unused",
    "validate",
    "with_option_signature",
]
