"""The native masked PPO (agents/native_ppo.py): the autoreset step never reaches the
loss, truncation is bootstrapped and termination is not, masks hold, a seed gives the
same run, and ``flowtest train`` writes a native checkpoint that plays as ``ppo:PATH``.

Tiny envs and a few hundred steps keep these fast; the learning figures are in
docs/benchmarks.md.
"""

from __future__ import annotations

import copy
import json
import signal
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from tests.testing_processes import start_until

torch = pytest.importorskip("torch")

import flowtest_env  # noqa: E402,F401
from agents.checkpoint import is_native_checkpoint, load_checkpoint  # noqa: E402
from agents.native_ppo import (  # noqa: E402
    Agent,
    NativeArgs,
    Rollout,
    Runner,
    advantages,
    collect_rollout,
    make_agent,
    masked_logits,
    minibatch_indices,
    ppo_update,
    train,
)
from experiments.cli.cli import main  # noqa: E402
from flowtest_env.encoding import make_encoder  # noqa: E402
from flowtest_env.wrappers import shared_position_slice  # noqa: E402

FLOWTEST = Path(sys.executable).parent / "flowtest"


def _runner(kind: str, max_steps: int = 3, n: int = 4, seed: int = 0) -> tuple[Runner, Agent, NativeArgs]:
    """A runner on small-reactive whose episodes end every few steps (``max_steps``)."""
    env: Any = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=n, vectorization_mode="vector_entry_point", max_steps=max_steps)
    torch.manual_seed(seed)
    where = shared_position_slice([make_encoder(g, "flat") for g in env.unwrapped.games])
    obs_size = int(env.single_observation_space.shape[0]) + (where.stop - where.start)
    agent = make_agent(obs_size, int(env.single_action_space.n), (16,), "gru" if kind == "recurrent-ppo" else "mlp", 8)
    args = NativeArgs(algo=kind, num_envs=n, num_steps=12, num_minibatches=2, update_epochs=2, hidden=(16,), gru_hidden=8)
    return Runner(env, agent, where, torch.device("cpu"), seed), agent, args


@pytest.mark.parametrize("kind", ["ppo", "recurrent-ppo"])
def test_the_autoreset_step_is_never_trained_on(kind: str) -> None:
    """With NEXT_STEP autoreset the step after an episode end is a reset whose action the
    env ignores. The rollout marks exactly those steps invalid, the MLP's minibatches hold
    exactly the valid steps, and whatever is recorded at an autoreset step (action, its
    log-probability, reward, mask) changes nothing in the update."""
    runner, agent, args = _runner(kind)
    first = collect_rollout(runner, 12)
    r = collect_rollout(runner, 12)  # a second rollout: the carried-over flags count too
    done = (r.terminated | r.truncated).numpy()
    done_before = np.concatenate([(first.terminated | first.truncated).numpy()[-1:], done[:-1]])
    np.testing.assert_array_equal(r.valid.numpy(), ~done_before)
    reset = ~r.valid.numpy()
    assert reset.sum() >= 4  # episodes of 3 steps: plenty of autoreset steps
    # the env's own contract at those steps: reward 0, neither terminated nor truncated
    assert (r.rewards.numpy()[reset] == 0).all() and not done[reset].any()
    # the MLP trains on every valid step once, and on no other
    g = torch.Generator().manual_seed(0)
    chosen = torch.cat(minibatch_indices(r.valid, 3, g)).numpy()
    assert sorted(chosen.tolist()) == np.flatnonzero(r.valid.numpy().reshape(-1)).tolist()
    # garbage at the autoreset steps: the update is bit-for-bit the same
    bad = copy.copy(r)
    inv = ~r.valid
    bad.actions = torch.where(inv, (r.actions + 1) % agent.n_actions, r.actions)
    bad.logprobs = torch.where(inv, torch.full_like(r.logprobs, -50.0), r.logprobs)
    bad.rewards = torch.where(inv, torch.full_like(r.rewards, 1e3), r.rewards)
    bad.masks = torch.where(inv.unsqueeze(-1), torch.ones_like(r.masks), r.masks)
    params = []
    for rollout in (r, bad):
        a = copy.deepcopy(agent)
        opt = torch.optim.Adam(a.parameters(), lr=1e-2)
        ppo_update(a, opt, args, rollout, torch.Generator().manual_seed(1))
        params.append([p.detach().clone() for p in a.parameters()])
    for p, q in zip(*params, strict=True):
        assert torch.equal(p, q)
    # and the same garbage at a valid step does change it (the check can fail)
    worse = copy.copy(r)
    k = int(np.flatnonzero(r.valid.numpy().reshape(-1))[0])
    worse.rewards = r.rewards.clone().reshape(-1)
    worse.rewards[k] = 1e3
    worse.rewards = worse.rewards.reshape(r.rewards.shape)
    a = copy.deepcopy(agent)
    ppo_update(a, torch.optim.Adam(a.parameters(), lr=1e-2), args, worse, torch.Generator().manual_seed(1))
    assert any(not torch.equal(p, q) for p, q in zip(a.parameters(), params[0], strict=True))


def _rollout(terminated: bool) -> Rollout:
    """One env, three steps: a step, the episode's last step (terminated or truncated),
    then the autoreset step."""
    f = torch.zeros
    return Rollout(
        obs=f((3, 1, 2)),
        masks=torch.ones((3, 1, 2), dtype=torch.bool),
        actions=torch.zeros((3, 1), dtype=torch.long),
        logprobs=f((3, 1)),
        values=torch.tensor([[0.5], [0.25], [2.0]]),
        rewards=torch.tensor([[0.1], [0.2], [0.0]]),
        terminated=torch.tensor([[False], [terminated], [False]]),
        truncated=torch.tensor([[False], [not terminated], [False]]),
        valid=torch.tensor([[True], [True], [False]]),
        starts=torch.tensor([[True], [False], [False]]),
        h0=f((1, 0)),
        next_value=torch.tensor([7.0]),
    )


def test_truncation_bootstraps_the_last_observation_and_termination_nothing() -> None:
    gamma, lam = 0.9, 0.8
    for terminated in (True, False):
        adv, ret = advantages(_rollout(terminated), gamma, lam)
        last = 0.2 + (0.0 if terminated else gamma * 2.0) - 0.25  # V(o_2) = 2.0: the episode's last observation
        assert adv[1, 0].item() == pytest.approx(last)
        assert adv[0, 0].item() == pytest.approx(0.1 + gamma * 0.25 - 0.5 + gamma * lam * last)
        assert ret[1, 0].item() == pytest.approx(last + 0.25)


def test_masked_logits_give_illegal_actions_no_probability() -> None:
    logits = torch.tensor([[3.0, 1.0, 2.0], [0.0, 0.0, 0.0]])
    mask = torch.tensor([[False, True, True], [False, False, False]])
    p = torch.softmax(masked_logits(logits, mask), dim=-1)
    assert p[0, 0].item() == 0.0 and p[0, 1:].sum().item() == pytest.approx(1.0)
    assert torch.isfinite(p[1]).all()  # a terminal state's empty mask (the autoreset step) stays defined
    runner, _, _ = _runner("ppo")
    r = collect_rollout(runner, 12)
    taken = r.masks.gather(-1, r.actions.unsqueeze(-1)).squeeze(-1)
    assert taken[r.valid].all()  # every trained action was legal


@pytest.mark.parametrize("algo", ["ppo", "recurrent-ppo"])
def test_a_seed_gives_the_same_run_and_the_checkpoint_plays_it(tmp_path: Path, algo: str) -> None:
    """Twice the same seed, once on the torch env and once on the NumPy env: the same
    tensors bit for bit (the two envs give the same runs)."""
    args = NativeArgs(
        env_id="FlowTest-SmallReactive-v0",
        algo=algo,
        total_steps=512,
        num_envs=8,
        num_steps=16,
        num_minibatches=2,
        hidden=(16,),
        gru_hidden=8,
        device="cpu",
        eval_every=256,
        env_backend="torch",
    )
    a = train(args, out=tmp_path / "a.zip", progress_bar=False)
    args.env_backend = "numpy"
    b = train(args, out=tmp_path / "b.zip", progress_bar=False)
    ca, cb = load_checkpoint(tmp_path / "a.zip"), load_checkpoint(tmp_path / "b.zip")
    assert ca.tensors.keys() == cb.tensors.keys()
    for k in ca.tensors:
        np.testing.assert_array_equal(ca.tensors[k], cb.tensors[k])
    assert a.evaluations == b.evaluations and a.steps == 512
    assert [s for s, _ in a.evaluations] == [0, 256, 512]
    assert ca.settings["network"]["kind"] == ("gru" if algo == "recurrent-ppo" else "mlp")
    assert ca.settings["training"]["seed"] == 0 and ca.settings["n_actions"] == a.agent.n_actions
    # the greedy score the trainer measured is the score of the saved file, played one env at a time
    from agents.registry import make_policy
    from experiments.evaluation.episodes import run_episode

    env = gym.make("FlowTest-SmallReactive-v0")
    policy = make_policy(f"ppo:{tmp_path / 'a.zip'}", env)
    t = run_episode(env, policy, "small-reactive", "ppo", 0, record=False)
    assert (t.verdict["system_objective"] == "met") == (a.final["train"]["met"] == 1.0)


def test_flowtest_train_native_writes_every_setting_logs_and_a_safe_checkpoint(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "m.zip"
    code = main(
        [
            "train",
            "small-reactive",
            "--steps",
            "1024",
            "--num-envs",
            "8",
            "--n-steps",
            "16",
            "--net-arch",
            "16",
            "--out",
            str(model),
            "--log-dir",
            str(tmp_path / "logs"),
            "--eval-every",
            "512",
            "--eval-episodes",
            "2",
            "--device",
            "cpu",
            "-q",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "--trainer native" in err and "--n-envs 8" in err and "--net-arch 16" in err and "--device cpu" in err
    assert "greedy on the env's tests" in out and f"--sut ppo:{model}" in out
    saved = json.loads(model.with_suffix(".json").read_text())
    assert saved["trainer"] == "native" and saved["steps"] == 1024 and saved["settings"]["n_envs"] == 8
    assert saved["native_args"]["num_envs"] == 8 and saved["device"] == "cpu"
    assert model.with_suffix(".png").stat().st_size > 5_000
    rows = (tmp_path / "logs" / "m" / "progress.csv").read_text().splitlines()  # the run's own folder, named after the model
    assert rows[0].startswith("step,") and "episode/met" in rows[0] and "eval/train_met" in rows[0]
    assert len(rows) > 4
    # the model file: JSON settings and .npy tensors only, nothing pickled
    assert is_native_checkpoint(model)
    with zipfile.ZipFile(model) as z:
        names = z.namelist()
    assert names[0] == "flowtest-policy.json" and all(n.startswith("tensors/") and n.endswith(".npy") for n in names[1:])
    code = main(["evaluate", "--env", "small-reactive", "--sut", f"ppo:{model}", "--episodes", "2", "--out", str(tmp_path / "r"), "-q"])
    assert code == 0, capsys.readouterr().err
    assert "warning" not in capsys.readouterr().err  # data, not code: no opt-in, no warning


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--lstm-hidden-size", "8"], "a setting of --trainer sb3"),
        (["--trainer", "sb3", "--device", "cpu"], "a setting of the native trainer"),
        (["--trainer", "sb3", "--log-dir", "logs"], "goes with the native trainer"),
        (["--algo", "maskable-ppo", "--trainer", "sb3", "--gru-hidden-size", "4"], "a setting of the native trainer"),
        (["--device", "tpu"], "device"),
        (["--count", "4"], "go with --pool"),
        (["--pool", "nonsense/5x5"], "unknown family"),
        (["--pool", "reachability1/5x5"], "--pool trains on a named pool's tests through FlowTest-RandomGrid-v0, not small-reactive"),
    ],
)
def test_bad_training_flags_are_one_error_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], says: str) -> None:
    out = tmp_path / "m.zip"
    try:
        code = main(["train", "small-reactive", "--out", str(out), *argv])
    except SystemExit as exc:
        code = int(exc.code or 0)
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    assert err.count("\n") == 1 and err.startswith("error: ") and says in err, err
    assert not out.exists()


def test_ctrl_c_while_training_leaves_nothing_half_written(tmp_path: Path) -> None:
    """SIGINT mid-training: exit 130, one line, and no model, curve, summary or temporary
    file in the output folder."""
    out = tmp_path / "out"
    out.mkdir()
    proc = start_until(
        [
            str(FLOWTEST),
            "train",
            "small-reactive",
            "--steps",
            "100000000",
            "--num-envs",
            "8",
            "--net-arch",
            "16",
            "--out",
            str(out / "m.zip"),
            "--log-dir",
            str(out / "logs"),
            "--device",
            "cpu",
        ],
        "training with",
        signal.SIGINT,
    )
    deadline = time.time() + 60
    while not (out / "logs" / "m" / "progress.csv").exists() and time.time() < deadline:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert stdout == "" and "Traceback" not in err
    left = sorted(p.name for p in out.iterdir())
    assert left == ["logs"], left  # no model, curve, summary, nor any .tmp
    assert all(not p.name.startswith(".") for p in (out / "logs" / "m").iterdir())
    rows = (out / "logs" / "m" / "progress.csv").read_text().splitlines()
    assert rows[0].startswith("step,") and all(r.count(",") == rows[0].count(",") for r in rows)


def test_an_interrupted_run_does_not_wait_for_the_tensorboard_thread(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A KeyboardInterrupt inside TensorBoard's queue can leave its writer thread unable to
    wake, so closing the writer after Ctrl-C could hang for good (it did, under load): an
    interrupted run drops the writer without waiting; a finished one closes it."""
    import torch.utils.tensorboard

    import agents.native_ppo as native_ppo

    closed: list[str] = []

    class Writer:
        def __init__(self, log_dir: str) -> None:
            self.log_dir = log_dir

        def add_scalar(self, tag: str, value: float, step: int) -> None:
            pass

        def close(self) -> None:
            closed.append(self.log_dir)

    monkeypatch.setattr(torch.utils.tensorboard, "SummaryWriter", Writer)
    args = NativeArgs(
        env_id="FlowTest-SmallReactive-v0", total_steps=256, num_envs=8, num_steps=16, num_minibatches=2, hidden=(16,), device="cpu", eval_every=0
    )
    train(args, progress_bar=False, log_dir=tmp_path / "done")
    assert closed == [str(tmp_path / "done")]
    calls = []

    def interrupted(*a: Any, **kw: Any) -> dict[str, float]:
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return ppo_update(*a, **kw)

    monkeypatch.setattr(native_ppo, "ppo_update", interrupted)
    with pytest.raises(KeyboardInterrupt):
        train(args, progress_bar=False, log_dir=tmp_path / "stopped")
    assert closed == [str(tmp_path / "done")] and len(calls) == 2
    assert (tmp_path / "stopped" / "progress.csv").read_text().count("\n") == 2  # the header and the one finished update


# --------------------------------------------------------------------------- prioritized level replay


def test_level_sampler_ranks_scores_weighs_staleness_and_plays_unseen_levels_first() -> None:
    from agents.native_ppo import LevelSampler

    s = LevelSampler(4, "pvl", temperature=1.0, staleness=0.0, seed=0)
    assert s.replay_distribution().sum() == 0.0  # nothing seen: nothing to replay
    first = s.choose(np.arange(3))
    assert len(set(first.tolist())) <= 3 and (first < 4).all()
    # two runs scored: env 0 plays level 2 (advantages 1, -1, 3: positive value loss 4/3), env 1 level 0 (all 0),
    # both starting at step 0; an invalid (autoreset) step of env 1 is ignored
    levels = np.array([[2, 0], [2, 0], [2, 0]])
    adv = np.array([[1.0, 0.0], [-1.0, 0.0], [3.0, 9.0]])
    valid = np.array([[True, True], [True, True], [True, False]])
    starts = np.array([[True, True], [False, False], [False, False]])
    s.update(levels, adv, valid, starts)
    assert s.scores[2] == pytest.approx(4 / 3) and s.scores[0] == 0.0 and s.seen.tolist() == [True, False, True, False]
    p = s.replay_distribution()  # temperature 1: h = 1/rank, normalized: level 2 rank 1, level 0 rank 2
    assert p.tolist() == pytest.approx([1 / 3, 0.0, 2 / 3, 0.0])
    gae = LevelSampler(4, "gae", seed=0)
    gae.update(levels, adv, valid, starts)
    assert gae.scores[2] == pytest.approx(5 / 3)  # mean |A|
    # staleness alone (rho = 1): proportional to the episodes since each level was last chosen
    t = LevelSampler(3, "pvl", staleness=1.0, seed=0)
    t.seen[:] = True
    t.episodes, t.last[:] = 10, [10, 6, 0]
    assert t.replay_distribution().tolist() == pytest.approx([0.0, 4 / 14, 10 / 14])
    # every level seen: every choice is a replay, drawn from the distribution
    t.scores[:] = [0.0, 5.0, 1.0]
    t.staleness = 0.0
    picks = t.choose(np.arange(200))
    assert t.replays == 200 and np.mean(picks == 1) > 0.95  # temperature 0.1: rank 1 dominates


def test_plr_training_samples_its_levels_and_is_seeded(tmp_path: Path) -> None:
    """level_sampling="plr": the env's tests are chosen by the sampler (every level is
    seen, replays happen, the log has the sampler's numbers), and a seed gives the same run."""
    args = NativeArgs(
        env_id="FlowTest-RandomGrid-v0",
        env_kwargs={"pool": "safety2/4x4", "split": "train", "count": 6},
        total_steps=1024,
        num_envs=8,
        num_steps=16,
        num_minibatches=2,
        hidden=(16,),
        device="cpu",
        eval_every=0,
        level_sampling="plr",
    )
    a = train(args, progress_bar=False)
    b = train(args, progress_bar=False)
    rows = [r for r in a.rows if "plr/levels_seen" in r]
    assert rows and rows[-1]["plr/levels_seen"] == 6 and rows[-1]["plr/replay_share"] > 0
    for k, v in a.agent.state_dict().items():
        assert torch.equal(v, b.agent.state_dict()[k]), k
    assert a.settings["training"]["level_sampling"] == "plr"
    with pytest.raises(ValueError, match="level_sampling"):
        train(NativeArgs(level_sampling="nope"), progress_bar=False)
    with pytest.raises(ValueError, match="NumPy env"):
        train(NativeArgs(level_sampling="plr", env_backend="torch"), progress_bar=False)


def test_batch_actor_plays_the_checkpoint_greedy_and_sampled(tmp_path: Path) -> None:
    """The saved model's batched policy gives the trainer's greedy score, and its sampled
    runs are seeded."""
    from agents.native_ppo import load_native
    from flowtest_env.scoring import play_batch

    args = NativeArgs(
        env_id="FlowTest-SmallReactive-v0", total_steps=512, num_envs=8, num_steps=16, num_minibatches=2, hidden=(16,), device="cpu", eval_every=0
    )
    result = train(args, out=tmp_path / "m.zip", progress_bar=False)
    model = load_native(tmp_path / "m.zip")
    vec: Any = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=1, vectorization_mode="vector_entry_point")
    games = list(vec.unwrapped.games)
    greedy = play_batch(model.batch_policy(), games, runs=1)
    assert float(np.mean(greedy["system_objective"] == "met")) == result.final["train"]["met"]
    one = play_batch(model.batch_policy(deterministic=False), games, runs=6, seed=3)
    two = play_batch(model.batch_policy(deterministic=False), games, runs=6, seed=3)
    assert (one["steps"] == two["steps"]).all() and (one["system_objective"] == two["system_objective"]).all()


def test_a_counts_checkpoint_plays_its_memory_everywhere(tmp_path: Path) -> None:
    """``memory="counts"``: the trainer's greedy score is the saved file's, played one env at
    a time (``ppo:PATH``, which rebuilds the counts) and batched (``batch_policy``)."""
    from agents.native_ppo import load_native
    from agents.registry import make_policy
    from experiments.evaluation.episodes import run_episode
    from flowtest_env.scoring import play_batch

    args = NativeArgs(
        env_id="FlowTest-SmallReactive-v0",
        memory="counts",
        total_steps=512,
        num_envs=8,
        num_steps=16,
        num_minibatches=2,
        hidden=(16,),
        device="cpu",
        eval_every=0,
    )
    result = train(args, out=tmp_path / "c.zip", progress_bar=False)
    model = load_native(tmp_path / "c.zip")
    assert model.flowtest_memory == "counts" and model.settings["memory"] == "counts"
    vec: Any = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=1, vectorization_mode="vector_entry_point")
    greedy = play_batch(model.batch_policy(), list(vec.unwrapped.games), runs=1)
    assert float(np.mean(greedy["system_objective"] == "met")) == result.final["train"]["met"]
    env = gym.make("FlowTest-SmallReactive-v0")
    t = run_episode(env, make_policy(f"ppo:{tmp_path / 'c.zip'}", env), "small-reactive", "ppo", 0, record=False)
    assert (t.verdict["system_objective"] == "met") == (result.final["train"]["met"] == 1.0)
    assert int(greedy["steps"][0, 0]) == t.verdict["steps"]


def test_the_network_reads_the_varying_entries_and_is_widened_for_play(tmp_path: Path) -> None:
    """``inputs="varying"`` trains on the observation entries that vary over the train tests
    (and the memory); the network returned and saved reads the whole observation, with zero
    weights on the others, and plays exactly as the narrow one did."""
    from agents.native.inputs import varying_columns, widen

    env: Any = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=1, vectorization_mode="vector_entry_point")
    table = np.asarray(env.unwrapped.pool.obs)
    cols = varying_columns(table.reshape(len(table), -1), memory=3)
    assert cols is not None and len(cols) < table.shape[1] + 3 and list(cols[-3:]) == [table.shape[1] + k for k in range(3)]
    assert varying_columns(np.array([[0.0, 1.0], [1.0, 0.0]])) is None
    narrow = make_agent(len(cols), 5, (8,), "mlp")
    wide = widen(narrow, torch.as_tensor(cols), table.shape[1] + 3)
    x = torch.rand(6, table.shape[1] + 3)
    for a, b in zip(
        narrow.step(x[:, torch.as_tensor(cols)], torch.zeros(6, 0), torch.zeros(6, dtype=torch.bool)),
        wide.step(x, torch.zeros(6, 0), torch.zeros(6, dtype=torch.bool)),
        strict=True,
    ):
        torch.testing.assert_close(a, b)
    dropped = np.setdiff1d(np.arange(table.shape[1] + 3), cols)
    assert float(wide.actor[0].weight.detach()[:, dropped].abs().sum()) == 0.0
    # end to end: the same seed trains "all" and "varying" to networks of the whole observation
    base = dict(env_id="FlowTest-SmallReactive-v0", total_steps=256, num_envs=8, num_steps=16, num_minibatches=2, hidden=(16,), device="cpu", eval_every=0)
    narrow_run = train(NativeArgs(**base, inputs="varying"), out=tmp_path / "v.zip", progress_bar=False)
    full_run = train(NativeArgs(**base, inputs="all"), progress_bar=False)
    assert narrow_run.agent.obs_size == full_run.agent.obs_size
    assert load_checkpoint(tmp_path / "v.zip").settings["training"]["inputs"] == "varying"


def test_validation_selects_the_checkpoint_and_until_stops_the_run(tmp_path: Path) -> None:
    args = NativeArgs(
        env_id="FlowTest-SmallReactive-v0", total_steps=1024, num_envs=8, num_steps=16, num_minibatches=2, hidden=(16,), device="cpu", eval_every=256
    )
    vec: Any = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=1, vectorization_mode="vector_entry_point")
    games = list(vec.unwrapped.games)
    result = train(args, out=tmp_path / "s.zip", progress_bar=False, validation=games)
    val = [(s, r["validation"]["met"]) for s, r in result.evaluations]
    best = max(m for _, m in val)
    assert result.selected_step == max(s for s, m in val if m == best)  # the latest of the best
    saved = load_checkpoint(tmp_path / "s.zip").settings["selected"]
    assert saved["step"] == result.selected_step and saved["validation_met"] == best
    assert len(result.eval_times) == len(result.evaluations) and result.eval_times == sorted(result.eval_times)
    assert any("eval/validation_met" in row for row in result.rows)
    seen: list[int] = []
    stopped = train(args, progress_bar=False, until=lambda step, rates: seen.append(step) or step >= 512)
    assert stopped.steps == 512 and seen == [0, 256, 512] and stopped.final == stopped.evaluations[-1][1]
