"""experiments/lab/bench_jax.py runs its FlowTest rows without the JAX side and refuses a
missing throwaway Python with one clear line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from experiments.lab import bench_jax


def test_flowtest_rows_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "figures.json"
    code = bench_jax.main(["--envs", "8", "--seconds", "0.02", "--repeat", "2", "--rows", "numpy flat", "numpy flat-uint8", "torch grid", "--json", str(out)])
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


def test_a_checkout_beside_in_a_worker(tmp_path: Path) -> None:
    """``--before DIR``: the rows of another checkout (here this one) in a worker process."""
    root = Path(bench_jax.__file__).resolve().parents[2]
    out = tmp_path / "figures.json"
    assert bench_jax.main(["--envs", "4", "--seconds", "0.02", "--repeat", "1", "--rows", "numpy grid", "--before", str(root), "--json", str(out)]) == 0
    fig = json.loads(out.read_text())
    assert [r["row"] for r in fig["rows"]] == ["numpy grid", "before: numpy grid"]
    assert fig["versions"]["before"]["flowtest_env"] == str(root / "flowtest_env")
    assert bench_jax.main(["--before", str(tmp_path)]) == 2
