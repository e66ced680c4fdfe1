"""experiments/lab/bench_jax.py runs its FlowTest rows without the JAX side and refuses a
missing throwaway Python with one clear line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from experiments.lab import bench_jax


def test_flowtest_rows_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "figures.json"
    code = bench_jax.main(["--envs", "8", "--seconds", "0.02", "--repeat", "2", "--rows", "numpy flat", "numpy flat-uint8", "torch grid",
                           "--json", str(out)])
    assert code == 0
    fig = json.loads(out.read_text())
    rows = {r["row"]: r for r in fig["rows"]}
    assert set(rows) == {"numpy flat", "numpy flat-uint8", "torch grid"}
    assert rows["numpy flat"]["obs"] == "float32[306]" and rows["numpy flat-uint8"]["obs"] == "uint8[306]"
    assert all(len(r["rates"]) == 2 and min(r["rates"]) > 0 for r in rows.values())
    assert "| FlowTest NumPy vector env" in capsys.readouterr().out


def test_a_missing_jax_python_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert bench_jax.main(["--jax-python", "/nonexistent/python"]) == 2
    assert capsys.readouterr().err.startswith("error: --jax-python /nonexistent/python: no such file")
