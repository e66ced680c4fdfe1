"""How numbers read in FlowTest's reports, tables and command output: one rule each.

Every share (a rate between 0 and 1) that a report, a table or a command line shows is
written by :func:`percent`; a share that is not known (no run met, nothing scored) is ``–``
everywhere. The digits and the space before ``%`` are the caller's (a table of means shows
one decimal, the evaluation's outcome lines none, HTML a non-breaking space).
"""

from __future__ import annotations

MISSING = "–"
"""What a report shows for a number that does not exist (``None``)."""


def percent(share: float | None, digits: int = 0, space: str = " ") -> str:
    """``share`` (0..1) as a percentage with ``digits`` decimals, ``space`` before the sign;
    :data:`MISSING` for ``None``.

    >>> percent(0.5), percent(0.1234, 1), percent(1.0, space="&nbsp;"), percent(None)
    ('50 %', '12.3 %', '100&nbsp;%', '–')
    """
    return MISSING if share is None else f"{100 * share:.{digits}f}{space}%"
