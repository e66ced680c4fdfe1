"""What each cap counts and how a message says it (:data:`CAP_NOUNS`, :func:`caps_text`), and
the error of a capped solve the time limit ended with neither a test nor a proof that none fits
(:class:`CapsTimeout`)."""

from __future__ import annotations

CAP_NOUNS = {"max_walls": "walls", "max_doors": "doors", "max_restrictions": "restrictions (walls and doors)"}
"""What each cap counts, for messages."""


def caps_text(caps: dict[str, int]) -> str:
    """``"at most 3 doors and at most 2 walls"``."""

    def noun(k: str, n: int) -> str:
        word = CAP_NOUNS[k].split(" (")[0]
        return word[:-1] if n == 1 else word

    parts = [f"at most {n} {noun(k, n)}" for k, n in caps.items()]
    return " and ".join(parts)


class CapsTimeout(TimeoutError):
    """A time limit that ended a capped solve with neither a test nor a proof that none fits.

    ``advice`` is what to try next: a gap (``--gap``) cannot help where no test was found, a
    higher cap or time limit can."""

    def __init__(self, message: str, advice: str = "raise the cap or --time-limit") -> None:
        super().__init__(message)
        self.advice = advice
