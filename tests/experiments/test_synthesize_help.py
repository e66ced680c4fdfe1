"""``flowtest synthesize --help`` says what ``--backend auto`` runs as the rule itself does
(synthesis.routing.backends.rules.AUTO_CPSAT_ROWS), never a band of rows measured long ago."""

from __future__ import annotations

import pytest

from experiments.cli.cli import main
from experiments.cli.synthesize import auto_rule
from synthesis.routing.backends.rules import AUTO_CPSAT_ROWS


def test_the_backend_help_states_auto_rule(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["synthesize", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert auto_rule() in text.replace("- ", "-")  # argparse may wrap inside a number range
    for mode, (lo, hi) in AUTO_CPSAT_ROWS.items():
        assert f"{mode} models of {lo:,}-{hi:,} rows" in auto_rule()
    assert "900-3,000" not in text
