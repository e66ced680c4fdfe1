"""Saved stable-baselines3 models as systems under test: ``ppo:PATH``.

The model (``MaskablePPO`` from sb3-contrib, or plain ``PPO``) is loaded lazily, so
FlowTest works without the ``rl`` extra until a ``ppo:`` policy is asked for. Maskable
models are given ``info["action_mask"]``, so they never pick a restricted action; a
plain PPO model may, and the env then leaves the SUT in place.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .base import Policy, PolicyError, action_mask_of, register_policy


def load_model(path: str | Path) -> Any:
    """Load a saved (Maskable)PPO model.

    Raises
    ------
    PolicyError
        If stable-baselines3 is missing or the file cannot be read.
    """
    p = Path(path)
    if not p.exists() and not p.with_suffix(".zip").exists():
        raise PolicyError(f"no saved model at {str(p)!r}")
    try:
        from sb3_contrib import MaskablePPO
    except ImportError:  # pragma: no cover - depends on the rl extra
        MaskablePPO = None
    try:
        from stable_baselines3 import PPO
    except ImportError as exc:  # pragma: no cover
        raise PolicyError("ppo:PATH needs the rl extra: pip install 'flowtest[rl]'") from exc
    if MaskablePPO is not None:
        try:
            return MaskablePPO.load(str(p), device="cpu")
        except Exception:  # noqa: BLE001 - fall back to plain PPO
            pass
    return PPO.load(str(p), device="cpu")


class PPOPolicy:
    """A trained model acting deterministically (its most likely legal action)."""

    def __init__(self, model: Any, name: str = "ppo") -> None:
        self.model = model
        self.name = name
        self.maskable = type(model).__name__ == "MaskablePPO"

    def reset(self, seed: int | None = None) -> None:
        """Stateless between episodes (an MLP policy)."""

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        if self.maskable:
            mask = action_mask_of(observation, info).astype(bool)
            action, _ = self.model.predict(observation, deterministic=True, action_masks=mask)
        else:
            action, _ = self.model.predict(observation, deterministic=True)
        return int(np.asarray(action).item())


@register_policy("ppo")
def _make_ppo(env: Any, arg: str) -> Policy:
    if not arg:
        raise PolicyError("ppo needs a model path: ppo:PATH")
    return PPOPolicy(load_model(arg), f"ppo:{arg}")
