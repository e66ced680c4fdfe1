"""The solver options: the routing model's options in four groups (the model, the budgets, the
measurement switches, how a solve runs), one validator with one rule per field, and the
synthesis options derived from the same groups.

* Every field of :class:`MilpOptions` is in exactly one group, every field of either options
  class has a rule, and :class:`SynthesisOptions`' budget and run fields are the routing ones
  (same names, types, defaults): they cannot drift apart.
* The same bad value gets the same reason through every door: ``SynthesisOptions`` (to
  :func:`synthesize`), the routing options (to :func:`solve_routing`), a problem file, and the
  command line.
"""

from __future__ import annotations

import math
from dataclasses import FrozenInstanceError, fields, replace
from pathlib import Path
from typing import Any, get_type_hints

import numpy as np
import pytest

from experiments.cli.cli import main
from synthesis.model.errors import ProblemError
from synthesis.model.option_rules import COUNT, FLAG, GAP, SECONDS, SEED, SETTING, THREADS, WORK, Rule
from synthesis.pipeline import SYNTHESIS_RULES, SynthesisOptions, milp_options, synthesize
from synthesis.pipeline import check_options as check_synthesis_options
from synthesis.problems.files import load_problem_file
from synthesis.problems.load import load_problem
from synthesis.problems.problem import build_graphs
from synthesis.routing.options import (
    BACKENDS,
    RULES,
    Budgets,
    MeasurementSwitches,
    MilpOptions,
    ModelOptions,
    RunOptions,
    check_options,
    group_of,
)
from synthesis.routing.solve import SOLVERS, solve_routing
from tests.testing_problems import SMALL_REACTIVE_TOML

GROUPS = (ModelOptions, Budgets, MeasurementSwitches, RunOptions)

PROBLEM = SMALL_REACTIVE_TOML  # ends in [environment]: a line appended goes there


def names(cls: type) -> set[str]:
    return {f.name for f in fields(cls)}


# --------------------------------------------------------------------------- the groups


def test_every_routing_option_is_in_exactly_one_group() -> None:
    seen: list[str] = [n for g in GROUPS for n in names(g)]
    assert len(seen) == len(set(seen)), "a field in two groups"
    assert set(seen) == names(MilpOptions)
    for group in GROUPS:
        assert issubclass(MilpOptions, group)


def test_the_measurement_switches_default_to_what_runs() -> None:
    """Each switch keeps the answer (a proof or a measured choice), so each is on, or ``auto``,
    unless someone measures without it."""
    for f in fields(MeasurementSwitches):
        assert f.default in (True, "auto"), f.name
    switches = MilpOptions()
    assert all(getattr(switches, n) in (True, "auto") for n in names(MeasurementSwitches))


def test_the_groups_are_frozen_values() -> None:
    options = MilpOptions(time_limit=5.0)
    with pytest.raises(FrozenInstanceError):
        options.time_limit = 6.0  # type: ignore[misc]
    with pytest.raises(FrozenInstanceError):
        SynthesisOptions().threads = 2  # type: ignore[misc]
    assert replace(options, flow_bound=False).flow_bound is False and options.flow_bound is True
    budgets = group_of(options, Budgets)
    assert isinstance(budgets, Budgets) and budgets.time_limit == 5.0 and names(Budgets) == set(vars(budgets))


def test_synthesis_options_are_the_routing_budgets_and_run_options() -> None:
    """Derived, not restated: the budget and run fields of the synthesis options are the
    routing ones (inherited), and a field of both classes has one type and one default."""
    assert issubclass(SynthesisOptions, Budgets) and issubclass(SynthesisOptions, RunOptions)
    assert names(Budgets) | names(RunOptions) <= names(SynthesisOptions)
    milp_hints, syn_hints = get_type_hints(MilpOptions), get_type_hints(SynthesisOptions)
    defaults = {f.name: f for f in fields(MilpOptions)}
    for f in fields(SynthesisOptions):
        if f.name in defaults and f.name != "caps":  # caps: the synthesis's replace the problem's
            assert syn_hints[f.name] == milp_hints[f.name], f.name
            assert f.default == defaults[f.name].default, f.name


def test_a_synthesis_passes_every_budget_and_run_option_to_the_routing_model() -> None:
    """Whatever a budget or run field is set to reaches the routing options (``time_limit``
    and ``threads`` with their fallbacks: the problem's time limit, one thread)."""
    problem = load_problem("small-reactive")

    def progress(line: str) -> None:
        pass

    given = SynthesisOptions(
        time_limit=7.0,
        after_first=2.0,
        mip_rel_gap=0.01,
        node_limit=99,
        work_limit=3.0,
        threads=2,
        random_seed=5,
        backend="highs",
        progress=progress,
        closed_loop=True,
    )
    milp = milp_options(problem, given)
    for name in names(Budgets) | names(RunOptions) | {"closed_loop"}:
        assert getattr(milp, name) == getattr(given, name), name
    plain = milp_options(problem, SynthesisOptions())
    assert plain.threads == 1 and plain.time_limit == problem.time_limit


# --------------------------------------------------------------------------- one validator


def test_every_field_has_a_rule() -> None:
    assert names(MilpOptions) <= set(RULES)
    assert names(SynthesisOptions) <= set(SYNTHESIS_RULES)
    assert all(isinstance(r, Rule) for r in (*RULES.values(), *SYNTHESIS_RULES.values()))


def test_the_backend_names_are_the_solver_table() -> None:
    """The validator's backend names are the table :func:`solve_routing` picks a solver from."""
    assert BACKENDS == ("auto", *SOLVERS)


def test_the_defaults_pass() -> None:
    check_options(MilpOptions())
    check_synthesis_options(SynthesisOptions())


BAD: list[tuple[str, Any, Rule]] = [
    ("time_limit", -1.5, SECONDS),
    ("time_limit", math.inf, SECONDS),
    ("time_limit", True, SECONDS),
    ("time_limit", 10**400, SECONDS),
    ("after_first", 0.0, SECONDS),
    ("mip_rel_gap", 1.5, GAP),
    ("mip_rel_gap", math.nan, GAP),
    ("threads", 0, THREADS),
    ("threads", 300, THREADS),
    ("threads", 2.0, THREADS),
    ("node_limit", 0, COUNT),
    ("work_limit", -1.0, WORK),
    ("random_seed", -1, SEED),
    ("closed_loop", "yes", FLAG),
]


@pytest.fixture(scope="module")
def products() -> Any:
    return build_graphs(load_problem("small-reactive"))[1]


@pytest.mark.parametrize(("name", "value", "rule"), BAD, ids=[f"{n}={v!r}"[:30] for n, v, _ in BAD])
def test_the_same_bad_value_gets_the_same_error_from_python(name: str, value: Any, rule: Rule, products: Any) -> None:
    """Through ``SynthesisOptions`` to :func:`synthesize` and through ``MilpOptions`` to
    :func:`solve_routing`: one message, naming the option and the reason."""
    reason = rule.reason(value)
    assert reason is not None and reason.startswith("must be ")
    expected = f"option {name} {reason}"
    with pytest.raises(ProblemError) as synthesis_door:
        synthesize(load_problem("small-reactive"), SynthesisOptions(**{name: value}))
    with pytest.raises(ProblemError) as routing_door:
        solve_routing(products, MilpOptions(**{name: value}))
    assert str(synthesis_door.value) == str(routing_door.value) == expected


CHOICES = [
    ("backend", "gurobi", "unknown solver backend 'gurobi' (option backend); expected one of auto, highs"),
    ("flow_rows", "rows", "unknown flow_rows option 'rows' (option flow_rows); expected one of auto, edge, cut"),
    ("feasibility", "sometimes", "unknown feasibility option 'sometimes' (option feasibility); expected one of auto, eager, lazy"),
    ("mode", "dynamic", "unknown routing mode 'dynamic' (option mode); expected one of static, reactive, mixed"),
    ("tie_places", "walls", "unknown tie_places 'walls' (option tie_places); expected one of none, all, static"),
]


@pytest.mark.parametrize(("name", "value", "start"), CHOICES, ids=[c[0] for c in CHOICES])
def test_a_misspelled_name_is_refused_before_any_work(name: str, value: str, start: str, products: Any) -> None:
    with pytest.raises(ProblemError) as routing_door:
        solve_routing(products, MilpOptions(**{name: value}))
    assert str(routing_door.value).startswith(start)
    if name == "backend":  # a synthesis option too: the same message
        with pytest.raises(ProblemError) as synthesis_door:
            synthesize(load_problem("small-reactive"), SynthesisOptions(backend=value))
        assert str(synthesis_door.value) == str(routing_door.value)


def test_synthesis_only_options_follow_their_rules() -> None:
    problem = load_problem("small-reactive")
    for name, value, rule in [("agent_iterations", 0, COUNT), ("max_graph_edges", -3, COUNT), ("setting", "bogus", SETTING)]:
        err = rule.error(value, f"option {name}")
        assert err is not None
        with pytest.raises(ProblemError) as info:
            synthesize(problem, SynthesisOptions(**{name: value}))
        assert str(info.value) == str(err)
    with pytest.raises(ProblemError, match=r"option caps must be a dict of max_walls, max_doors, max_restrictions, not 3"):
        synthesize(problem, SynthesisOptions(caps=3))  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match=r"unknown cap 'max_windows' \(option caps\)"):
        check_options(MilpOptions(caps={"max_windows": 1}))


def test_a_numpy_flag_is_a_flag() -> None:
    """The routing model's own switches may come out of numpy (``np.bool_``)."""
    check_options(MilpOptions(reductions=np.bool_(False)))


# --------------------------------------------------------------------------- the problem file and the command line


@pytest.mark.parametrize("value", [-1.5, 0.0, math.inf, math.nan])
def test_a_problem_files_time_limit_gets_the_same_reason(tmp_path: Path, value: float) -> None:
    path = tmp_path / "p.toml"
    path.write_text(PROBLEM + f"time_limit = {value!r}\n")
    with pytest.raises(ProblemError) as file_door:
        load_problem_file(path)
    with pytest.raises(ProblemError) as option_door:
        check_synthesis_options(SynthesisOptions(time_limit=value))
    reason = SECONDS.reason(value)
    assert reason is not None
    assert str(file_door.value).startswith("`time_limit` in [environment]") and str(file_door.value).endswith(reason)
    assert str(option_door.value) == f"option time_limit {reason}"


def test_a_problem_files_setting_gets_the_same_reason(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text(PROBLEM + 'setting = "bogus"\n')
    with pytest.raises(ProblemError) as file_door:
        load_problem_file(path)
    assert str(file_door.value).startswith("unknown obstacle setting 'bogus' (`setting` in [environment]")
    assert str(file_door.value).endswith("); expected one of instantaneous, accumulative")


FLAGS = [
    ("--time-limit", "-1.5", SECONDS, -1.5),
    ("--time-limit", "0", SECONDS, 0.0),
    ("--time-limit", "inf", SECONDS, math.inf),
    ("--after-first", "-2", SECONDS, -2.0),
    ("--gap", "1.5", GAP, 1.5),
    ("--threads", "0", THREADS, 0),
]


@pytest.mark.parametrize(("flag", "text", "rule", "value"), FLAGS, ids=[f"{f} {t}" for f, t, _, _ in FLAGS])
def test_a_flag_gets_the_same_reason_as_the_option(flag: str, text: str, rule: Rule, value: Any, capsys: pytest.CaptureFixture[str]) -> None:
    """``flowtest synthesize --time-limit -1.5``: one ``error:`` line with the reason the
    option ``time_limit=-1.5`` gets, exit code 2, before any work."""
    with pytest.raises(SystemExit) as exc:
        main(["synthesize", "small-reactive", flag, text])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    reason = rule.reason(value)
    assert reason is not None
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and f"argument {flag}: {reason}" in lines[0], err


def test_a_flag_that_is_no_number_says_what_was_expected(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["synthesize", "small-reactive", "--time-limit", "soon"])
    assert exc.value.code == 2
    assert "argument --time-limit: must be a positive finite number of seconds, not 'soon'" in capsys.readouterr().err
