"""``flowtest train ENV --steps N --out PATH``: train a PPO system under test against a test.

This module parses the arguments and calls the library (:mod:`experiments.training`:
:func:`~experiments.training.system.train_native`, :func:`~experiments.training.system.train`,
their settings in :mod:`experiments.training.settings`).

``ENV`` is anything ``flowtest evaluate --env`` takes (a registered ID, a built-in name, a
problem file, an artifact file); ``--pool NAME`` (with ``FlowTest-RandomGrid-v0``) trains
on the first ``--count`` tests of a pool's ``--split``: a standard pool id
(``reachability1/5x5-v2``: its shipped tests, loaded in seconds) or an on-demand pool name
(``reachability1/5x5``: built on demand, cached). With ``--pool`` both trainers finish by
playing the greedy policy on those tests and on ``--heldout-count`` tests of the pool's
held-out ``test`` split, and print each score beside the random floor of the same tests.

**Two trainers** (``--trainer``):

* ``native`` (default): FlowTest's own masked PPO (:mod:`agents.native_ppo`), stepping
  ``--n-envs`` runs at once in the NumPy vector env, on ``--device`` (``auto``, ``cpu``,
  ``cuda``). ``--algo ppo`` (an MLP with the visited-places memory) or
  ``--algo recurrent-ppo`` (a GRU). It evaluates the greedy policy on the env's own tests
  (a pool's train tests) and, with ``--pool``, on ``--heldout-count`` tests of the pool's
  test split; logs go to a new folder of the run inside ``--log-dir`` (``progress.csv``, and
  TensorBoard), named after the model, so no run writes over another's. The model is a
  native checkpoint: tensors and plain settings, loaded without unpickling
  (:mod:`agents.checkpoint`).
* ``sb3``: sb3-contrib's ``MaskablePPO`` (``--algo maskable-ppo``) or ``RecurrentPPO``
  (``--algo recurrent-ppo``, an LSTM, no masks) on a few single envs in one process; the
  model is a stable-baselines3 zip, which loading unpickles (so ``ppo:PATH`` loads it only
  with ``--trust-model``).

Everything the trainers add to the environment is an env option, printed at the start
and saved with the model:

* ``memory="visited"`` (default here): the places the SUT has occupied this episode
  appended to the observation (:class:`flowtest_env.wrappers.VisitedPlaces`); without
  memory no policy passes a reactive test that makes the SUT pass a cell twice;
* ``shaping`` (sb3: 10 by default here; native: 0, the vector env's option when it has
  one): potential-based shaping towards the SUT's own objective
  (:class:`flowtest_env.wrappers.DistanceShaping`);
* ``obs_kind`` and ``pad_to``: the observation (``"padded"`` gives one shape for every grid
  test up to ``pad_to x pad_to``, so one policy plays many tests).

Every setting of :data:`NATIVE_DEFAULTS` and :data:`DEFAULTS` (sb3) is a flag
(``--learning-rate``, ``--memory none``, ...); a flag of the other trainer is refused.
Writes the model (``PATH``, a ``.zip``), its training curve (``PATH`` with ``.png``) and
``PATH`` with ``.json`` (every setting, time, the curve's data). Load the model as a SUT
with ``--sut ppo:PATH``. See docs/training.md.

Needs the ``rl`` extra (``pip install 'flowtest[rl]'``: torch, stable-baselines3,
sb3-contrib, tensorboard).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from experiments.evaluation.episodes import env_named
from experiments.outputs import check_log_dir, check_output_path
from experiments.training.rl import require_native
from experiments.training.settings import ALGOS, DEFAULTS, NATIVE_ALGOS, NATIVE_DEFAULTS, TRAINERS, check_settings, flag_of, native_settings
from experiments.training.system import FLOOR_RUNS, heldout_games, train, train_native
from synthesis.model.errors import ProblemError

from .arguments import nonnegative_int, positive_int
from .command import Command
from .exits import EXIT_OK


def _net_arch(text: str) -> list[int]:
    try:
        return [int(w) for w in text.split(",") if w.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected layer widths such as 64,64, not {text!r}") from None


SETTING_HELP: dict[str, str] = {
    "algo": f"algorithm: native {', '.join(NATIVE_ALGOS)}; sb3 {', '.join(ALGOS)}",
    "n_envs": "envs stepped together",
    "n_steps": "rollout steps per env",
    "batch_size": "minibatch size (steps)",
    "learning_rate": "learning rate",
    "gamma": "discount",
    "ent_coef": "entropy bonus",
    "n_epochs": "epochs per rollout",
    "net_arch": "hidden layer widths, comma-separated",
    "lstm_hidden_size": "LSTM width (sb3 recurrent-ppo only)",
    "gru_hidden_size": "GRU width (native recurrent-ppo)",
    "gae_lambda": "GAE lambda",
    "clip_range": "PPO ratio clip",
    "vf_coef": "value loss weight",
    "max_grad_norm": "gradient clip",
    "device": "auto (cuda when torch sees one), cpu, cuda, cuda:N",
    "threads": "torch CPU threads",
    "env_backend": "who steps the tests: torch (the torch env on --device), numpy (the NumPy vector env); auto: numpy on the CPU, else torch",
    "shaping": "env option: shaping scale, 0 = off",
    "memory": "env option: the SUT's memory, none, visited or counts (how often, capped)",
    "obs_kind": "env option: flat, grid or padded",
    "pad_to": "env option: grid side of obs_kind=padded",
}


def _shown(value: Any) -> str:
    return ",".join(map(str, value)) if isinstance(value, list) else str(value)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest train``'s arguments."""
    p.add_argument(
        "ENV",
        nargs="?",
        help="environment: a registered ID (FlowTest-Maze2-v0), a built-in name (maze2), a problem file (mine.toml) or an artifact file; "
        f"with --pool it may be left out ({POOL_ENV}, the env of the pools)",
    )
    p.add_argument(
        "--trainer",
        choices=TRAINERS,
        default="native",
        help="native: FlowTest's batched masked PPO (default; a native checkpoint); sb3: stable-baselines3 (an SB3 zip, which loading unpickles)",
    )
    p.add_argument("--steps", type=positive_int, default=None, help="training time steps (default: native 1500000, sb3 50000)")
    p.add_argument("--out", type=Path, required=True, help="model file (.zip); the curve goes next to it (.png)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed (default 0)")
    p.add_argument("--pool", metavar="NAME", default=None, help="train on a named pool's tests (FlowTest-RandomGrid-v0), e.g. reachability1/5x5")
    p.add_argument("--split", choices=("train", "validation", "test"), default=None, help="the pool's split to train on (default train)")
    p.add_argument("--count", type=positive_int, default=None, help="tests of the split (default 128)")
    p.add_argument(
        "--heldout-count",
        type=nonnegative_int,
        default=None,
        help="with --pool: held-out tests of the pool's test split evaluated during training (default 32; 0: none)",
    )
    p.add_argument("--eval-every", type=nonnegative_int, default=250_000, help="native: steps between greedy evaluations (default 250000; 0: at the end only)")
    p.add_argument(
        "--log-dir",
        type=Path,
        default=None,
        help="native: write progress.csv and TensorBoard logs into a new folder of this run inside this "
        "folder, named after the model (DIR/NAME, or DIR/NAME-2... when taken: an earlier run's logs "
        "are never replaced); not a symbolic link",
    )
    p.add_argument(
        "--eval-episodes",
        type=nonnegative_int,
        default=None,
        help="single-env evaluation runs after training (default 100, 0 with --pool (the greedy evaluation on the tests is the score))",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing model, curve or summary")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    g = p.add_argument_group("settings (printed at the start and saved in the .json; defaults per trainer)")
    keys = list(dict.fromkeys([*NATIVE_DEFAULTS, *DEFAULTS]))
    for key in keys:
        native, sb3 = NATIVE_DEFAULTS.get(key), DEFAULTS.get(key)
        where = "; ".join(f"{name} {_shown(v)}" for name, v in (("native", native), ("sb3", sb3)) if v is not None)
        kw: dict[str, Any] = {"default": None, "help": f"{SETTING_HELP[key]} (default: {where})"}
        default = native if native is not None else sb3
        if isinstance(default, list):
            kw["type"] = _net_arch
        elif key == "algo":
            kw["choices"] = tuple(dict.fromkeys([*NATIVE_ALGOS, *ALGOS]))
        elif key in ("memory", "obs_kind", "env_backend"):
            kw["choices"] = {"memory": ("none", "visited", "counts"), "obs_kind": ("flat", "grid", "padded"), "env_backend": ("auto", "torch", "numpy")}[key]
        elif key == "device":
            kw["type"] = str
        else:
            kw["type"] = type(default)
        names = [flag_of(key)] + (["--num-envs"] if key == "n_envs" else [])
        g.add_argument(*names, dest=key, **kw)


POOL_ENV = "FlowTest-RandomGrid-v0"
"""The environment whose tests ``--pool`` names (the others take no pool options)."""


def _pool_options(args: argparse.Namespace) -> dict[str, Any]:
    """The env options of ``--pool``: a standard pool id (``reachability1/5x5-v2``: its
    shipped tests are loaded, nothing synthesized) or an on-demand pool name."""
    if args.pool is None:
        if args.split is not None or args.count is not None or args.heldout_count:
            raise ProblemError("--split, --count and --heldout-count go with --pool")
        return {}
    from flowtest_env.pools import parse_pool, pool_seeds
    from flowtest_env.standard_pools import is_standard, standard_pool

    options = {"pool": args.pool, "split": args.split or "train", "count": args.count or 128}
    try:
        if is_standard(args.pool):
            standard_pool(args.pool)  # a known id and version
        else:
            parse_pool(args.pool)
        pool_seeds(args.pool, options["split"], options["count"])  # a -v2 pool ships so many tests per split
        if args.heldout_count != 0:
            pool_seeds(args.pool, "test", 32 if args.heldout_count is None else args.heldout_count)
    except ValueError as exc:
        raise ProblemError(f"--pool {args.pool}: {exc}") from None
    return options


def run(args: argparse.Namespace) -> int:
    """Train, save, evaluate; print every setting used, then where the model and its curve are."""
    given = {k: getattr(args, k) for k in dict.fromkeys([*NATIVE_DEFAULTS, *DEFAULTS]) if getattr(args, k) is not None}
    pool = _pool_options(args)
    if args.ENV is None:
        if not pool:
            raise ProblemError("give the environment to train on (ENV: flowtest train FlowTest-Maze2-v0 ...) or a pool (--pool reachability1/5x5-v2)")
        args.ENV = POOL_ENV
    if args.trainer == "sb3":
        if args.log_dir is not None:
            raise ProblemError("--log-dir goes with the native trainer (--trainer native)")
        unknown = set(given) - set(DEFAULTS)
        if unknown:
            raise ProblemError(f"{', '.join(flag_of(k) for k in sorted(unknown))}: a setting of the native trainer, not of --trainer sb3")
        settings = {**DEFAULTS, **given}
        check_settings(settings)
    else:
        require_native()
        settings = native_settings(given)
    if pool and args.ENV != POOL_ENV:
        raise ProblemError(
            f"--pool trains on a named pool's tests through {POOL_ENV}, not {args.ENV}: "
            f"flowtest train {POOL_ENV} --pool {args.pool} ... (or drop --pool to train on {args.ENV})"
        )
    env_named(args.ENV, **pool).close()  # a bad environment is refused before anything else
    model_path = args.out if args.out.suffix == ".zip" else args.out.with_suffix(".zip")
    for path, what in ((model_path, "model"), (model_path.with_suffix(".png"), "curve"), (model_path.with_suffix(".json"), "training summary")):
        check_output_path(path, args.force, what)
    if args.log_dir is not None:
        check_log_dir(args.log_dir)
    steps = args.steps if args.steps is not None else (50_000 if args.trainer == "sb3" else 1_500_000)
    shown = " ".join(f"{flag_of(k)} {_shown(v)}" for k, v in settings.items())
    extra = "".join(f" --{k} {v}" for k, v in pool.items())
    sys.stderr.write(f"flowtest: training with --trainer {args.trainer} --steps {steps} --seed {args.seed}{extra} {shown}\n")
    sys.stderr.flush()
    heldout: list[Any] = []
    if pool:
        n_heldout = 32 if args.heldout_count is None else args.heldout_count
        if n_heldout:
            heldout = heldout_games(pool["pool"], n_heldout, progress=not args.quiet)
    eval_episodes = args.eval_episodes if args.eval_episodes is not None else (0 if pool else 100)
    if args.trainer == "sb3":
        s = train(args.ENV, steps, args.out, args.seed, progress_bar=not args.quiet, eval_episodes=eval_episodes, env_kwargs=pool, heldout=heldout, **given)
        lines = [f"trained {s['steps']} steps in {s['seconds']:.1f} s"]
    else:
        s = train_native(
            args.ENV,
            steps,
            args.out,
            args.seed,
            progress_bar=not args.quiet,
            eval_episodes=eval_episodes,
            env_kwargs=pool,
            heldout=heldout,
            log_dir=args.log_dir,
            eval_every=args.eval_every,
            **given,
        )
        lines = [
            f"trained {s['steps']} steps in {s['seconds']:.1f} s ({s['steps_per_second']:,.0f} steps/s on "
            f"{s['device']}, evaluations {s['eval_seconds']:.1f} s more)"
        ]
    lines += score_lines(s, pool, len(heldout))
    if s["success_rate"] is not None:
        lines.append(f"system objective met in {100 * s['success_rate']:.0f} % of {s['eval_episodes']} evaluation runs")
    used = ", ".join(f"{k}={_shown(v)}" for k, v in s["settings"].items())
    trust = " --trust-model" if args.trainer == "sb3" else ""  # an SB3 zip is unpickled when loaded
    lines += [
        f"settings: {used}",
        f"model: {s['model']} (use --sut ppo:{s['model']}{trust})",
        f"curve: {s['curve']}",
        f"settings and curve data: {Path(s['model']).with_suffix('.json')}",
    ]
    if s.get("log_dir") is not None:
        lines.append(f"logs: {s['log_dir']} (progress.csv; tensorboard --logdir {args.log_dir})")
    sys.stdout.write("\n".join(lines) + "\n")
    return EXIT_OK


def score_lines(s: dict[str, Any], pool: dict[str, Any], n_heldout: int) -> list[str]:
    """The greedy scores of a training summary, each beside its tests' random floor: ``greedy
    on 32 held-out tests: system objective met 46.9 % (random: 21.9 %), ...``."""
    lines = []
    for split, what in (("train", f"the {pool['count']} {pool['split']} tests" if pool else "the env's tests"), ("heldout", f"{n_heldout} held-out tests")):
        if split in s["final"]:
            r = s["final"][split]
            floor = s.get("floor", {}).get(split)
            beside = "" if floor is None else f" (random: {100 * floor:.1f} %, {FLOOR_RUNS} runs per test)"
            lines.append(
                f"greedy on {what}: system objective met {100 * r['met']:.1f} %{beside}, test objective realized "
                f"{100 * r['realized']:.1f} %, {r['restrictions']:.1f} restrictions per run"
            )
    return lines


COMMAND = Command("train", "train a PPO system under test against a synthesized test", add_arguments, run)
