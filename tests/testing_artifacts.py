"""Helpers for tests that look at the artifact an environment plays."""

from __future__ import annotations

from typing import Any


def played_artifact(env: Any) -> Any:
    """The :class:`~synthesis.artifacts.artifact.TestArtifact` a FlowTest env plays."""
    from synthesis.artifacts.artifact import TestArtifact

    art = env.unwrapped.artifact
    assert isinstance(art, TestArtifact)
    return art
