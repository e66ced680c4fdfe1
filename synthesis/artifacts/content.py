"""The content key of a test: which game a policy plays, whatever the test is called.

Two tests have the same content key exactly when a policy plays the same game in both:
the same transition system (states, moves, actions, labels, the grid layout it is drawn
on), the same objectives and automata (the histories the environment tracks), the same
restrictions (static walls and reactive doors, history by move) and the same test agent
(its cells, parks and strategy table). What does not change the game is left out: the
test's name, the seed and attempt it was drawn from, its description, the solver's
summary and statistics (status, flow, timings, model sizes), provenance and other extras,
and the display names of automaton states.

The key is the SHA-256 (hex) of one canonical JSON document (sorted keys, no spaces,
ASCII) of those fields, written as the artifact file writes them
(:meth:`synthesis.artifacts.artifact.TestArtifact.to_dict`, docs/artifact-schema.md):
every set is a sorted list there (a state's labels, the blocked cells, the layout's
tokens, each history's restricted moves, the static walls), states, moves and histories
are numbered as FlowTest builds them from the problem (a grid's cells in row-major order),
so the same game always comes out as the same document. The document starts with
:data:`KEY_FORMAT`, which changes if the definition ever does.

Example::

    from synthesis import load_problem, synthesize, summary_of, artifact_of
    from synthesis.artifacts.content import content_key

    test = synthesize(load_problem("small-reactive"))
    key = content_key(artifact_of(test, summary_of(test)))   # 64 hex digits
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from .artifact import TestArtifact, dba_to_dict

__all__ = ["KEY_FORMAT", "content_document", "content_key"]

KEY_FORMAT = "flowtest-content/1"
"""The version of the content key's definition (the document's ``format``)."""


def content_document(art: TestArtifact) -> dict[str, Any]:
    """The plain data the content key hashes: the game of ``art`` without its name, seed,
    summary, extras or automaton state names (module docstring)."""

    def table(name: str) -> dict[str, Any]:
        dba = {"system": art.system_automaton, "test": art.test_automaton, "histories": art.histories}[name]
        return {k: v for k, v in dba_to_dict(dba).items() if k != "names"}

    return {
        "format": KEY_FORMAT,
        "kind": art.kind,
        "objectives": {"system": art.objectives["system"], "test": art.objectives["test"]},
        "system": art.system.to_dict(),
        "letters": [sorted(a) for a in art.letters],
        "automata": {name: table(name) for name in ("system", "test", "histories")},
        "restrictions": art.strategy.to_dict(),
        "agent": art.agent,
    }


def content_key(art: TestArtifact) -> str:
    """SHA-256 (hex) of :func:`content_document`: equal for two tests exactly when a policy
    plays the same game in both (module docstring)."""
    text = json.dumps(content_document(art), sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("ascii")).hexdigest()
