"""Training and sweep throughput, measured in one run on one machine, with the ratios that matter.

    python -m benchmarks.bench_speed                 # about 8 minutes on 2 cores
    python -m benchmarks.bench_speed --repeats 2     # quicker, noisier

Prints, for CartPole-v1 (discrete script) and Hopper-v4 (continuous script):
  - raw env stepping: one gym.make env, and the training script's own vector env, random actions;
  - training steps per second at guidance 1 (PPO) and 1.1 (PGG), eager and with --compile, the PGG
    overhead of each, and what --compile costs once (its compile, with inductor's cache cold and
    warm) and after how many steps it has paid that back;
  - the γ sweep: env steps per second of the batched evaluator and of the one-env sequential
    reference on the same cells, their ratio, and the batched rate against raw env stepping.
The four configurations train side by side in one process, taking turns one iteration at a time
(`interleaved_training`), in alternating order across repeats. Their SPS leaves out the setup and
the first iteration (where --compile compiles) of every run; the compile time is measured apart, as
the extra wall time of a two-iteration run with --compile in a fresh process. This machine class's
speed drifts by tens of percent over minutes, and ratios of whole runs made seconds apart swung from
-25% to +57%; the same iteration of the two runs is milliseconds to a second apart. The PGG overhead
is the ratio of their summed iteration times, and of their summed PPO updates (where PGG's extra
compute is), with bootstrap intervals over the pairs. SPS figures are each configuration's best
repeat; the speed-ups (over CleanRL, of --compile) are medians over repeats of the ratio within one
repeat.

The speed-up over CleanRL is only meaningful measured in the same run: this machine class's speed
varies up to 2x with the load of its host. Given a CleanRL checkout and a Python that runs it
(gymnasium 0.29), CleanRL's ppo.py and ppo_continuous_action.py join the alternation, one thread each:

    python -m benchmarks.bench_speed --cleanrl-dir ~/cleanrl/cleanrl --cleanrl-python ~/cleanrl-venv/bin/python

Without it, the speed-up is taken against the figures the issue quotes for this machine class
(ppo.py 3.4k-4.0k SPS on CartPole-v1, ppo_continuous_action.py about 780 SPS on Hopper-v4).
"""

import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import tyro

import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import tasks
from pgg_utils.arguments import DEFAULT_GAMMAS
from pgg_utils.checkpoints import latest_checkpoint
from pgg_utils.evaluation import GuidedPolicy, evaluate_cell, load_any_checkpoint
from pgg_utils.runs import train_in_process

CLEANRL_SPS = {"CartPole-v1": (3400, 4000), "Hopper-v4": (780, 780)}
CLEANRL_SCRIPTS = {"CartPole-v1": "ppo.py", "Hopper-v4": "ppo_continuous_action.py"}


@dataclass
class Args:
    repeats: int = 6
    """alternating repeats of each training configuration (SPS: the fastest; ratios: the median)"""
    cartpole_steps: int = 40_960
    """training steps per CartPole measurement"""
    hopper_steps: int = 16_384
    """training steps per Hopper measurement"""
    sweep_episodes: int = 10
    """episodes per γ in the sweep measurement (the paper's protocol: 50)"""
    sweep_checkpoints: tuple[str, ...] = ()
    """trained checkpoints to time the sweep on, at most one per env; an env without one gets a
    checkpoint trained here for 4 iterations, whose short, ragged episodes leave the evaluator's
    batch mostly empty and understate its rate"""
    cleanrl_dir: str | None = None
    """folder holding CleanRL's ppo.py and ppo_continuous_action.py, to time them in the same run"""
    cleanrl_python: str = sys.executable
    """the Python that runs CleanRL's scripts (they need gymnasium 0.29)"""


def env_rates(module, env_id: str, train_args, steps: int = 20_000, repeats: int = 4) -> tuple[float, float]:
    """Steps/s of one gym.make env and of the training script's vector env (with its wrappers), on
    the same pre-drawn random actions, measured alternately; the best of `repeats` each. Sampling
    actions inside the timed loop, or timing one env after the other, biased an earlier version."""
    env = module.make_env(env_id)()
    env.action_space.seed(0)
    actions = np.stack([env.action_space.sample() for _ in range(1000)])
    num_envs = train_args.num_envs
    if module is ppo_pgg_discrete:
        envs = tasks.make_vector_env(module.make_env, env_id, num_envs, 0)
    else:
        wrap = lambda env: module.training_env(env, train_args.discount, train_args.reward_clip)
        envs = tasks.make_vector_env(module.make_env, env_id, num_envs, 0, wrap=wrap)
    batched_actions = np.stack([np.roll(actions, k, axis=0) for k in range(num_envs)], axis=1)

    def single() -> float:
        env.reset(seed=0)
        start = time.perf_counter()
        for i in range(steps):
            _, _, terminated, truncated, _ = env.step(actions[i % 1000])
            if terminated or truncated:
                env.reset()
        return steps / (time.perf_counter() - start)

    def vector() -> float:
        envs.reset(seed=0)
        start = time.perf_counter()
        for i in range(steps // num_envs):
            envs.step(batched_actions[i % 1000])
        return steps // num_envs * num_envs / (time.perf_counter() - start)

    best = {single: 0.0, vector: 0.0}
    for k in range(repeats):
        for measure in (single, vector) if k % 2 == 0 else (vector, single):
            best[measure] = max(best[measure], measure())
    return best[single], best[vector]


def interleaved_training(module, runs: list) -> list[dict[str, list[float]]]:
    """Trains one agent per Args in `runs`, in threads that take turns one iteration at a time, and
    returns, per run, the durations in seconds of its turns ("turns") and of its PPO updates
    ("updates"). Only the thread whose turn it is runs; the others wait on a lock, so each turn is
    timed as if alone. A turn starts at a call of `collect_rollout`, so turn k is iteration k's
    rollout, GAE, update and logging; the first turn is the setup, the last ends with the final
    checkpoint. The same iteration of the runs is milliseconds (CartPole) to a second (Hopper) apart,
    so this machine's drift, tens of percent over minutes, cancels in their ratio; whole runs seconds
    apart could not resolve a 5% difference. The runs share the global random generators, so none
    reproduces its solo run's learning curve: this is for timing only."""
    turn = threading.Condition()
    holder, finished, errors = [0], [False] * len(runs), []
    durations = [{"turns": [], "updates": []} for _ in runs]
    local = threading.local()
    collect_rollout, ppo_update = module.collect_rollout, module.ppo_update

    def wait_for_turn(me: int) -> None:
        with turn:
            turn.wait_for(lambda: holder[0] == me)
        local.start = time.perf_counter()

    def end_turn(me: int, last: bool = False) -> None:
        durations[me]["turns"].append(time.perf_counter() - local.start)
        with turn:
            finished[me] = last
            others = [k % len(runs) for k in range(me + 1, me + len(runs))]
            holder[0] = next((k for k in others if not finished[k]), me)
            turn.notify_all()

    def collect_rollout_in_turn(*args, **kwargs):
        end_turn(local.me)
        wait_for_turn(local.me)
        return collect_rollout(*args, **kwargs)

    def timed_ppo_update(*args, **kwargs):
        start = time.perf_counter()
        stats = ppo_update(*args, **kwargs)
        durations[local.me]["updates"].append(time.perf_counter() - start)
        return stats

    def run(me: int, args) -> None:
        local.me = me
        wait_for_turn(me)
        try:
            with tempfile.TemporaryDirectory() as tmp:
                args.output_dir = tmp
                train_in_process(module, args)
        except BaseException as e:
            errors.append(e)
        finally:
            end_turn(me, last=True)

    module.collect_rollout, module.ppo_update = collect_rollout_in_turn, timed_ppo_update
    try:
        threads = [threading.Thread(target=run, args=(me, args)) for me, args in enumerate(runs)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    finally:
        module.collect_rollout, module.ppo_update = collect_rollout, ppo_update
    if errors:
        raise errors[0]
    return durations


def cleanrl_sps(args: Args, env_id: str, run) -> float:
    """CleanRL's steps per second after its first iteration, as `steady_sps` counts ours, run with one
    torch thread like ours, for `run`'s steps and batch (our defaults, which are CleanRL's)."""
    batch_size = run.num_envs * run.num_steps
    script = Path(args.cleanrl_dir, CLEANRL_SCRIPTS[env_id]).resolve()
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run(
            [args.cleanrl_python, str(script), "--env-id", env_id, "--total-timesteps", str(run.total_timesteps),
             "--no-cuda"],
            cwd=tmp, env={**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"},
            capture_output=True, text=True,
        )  # fmt: skip
    sps = [int(s) for s in re.findall(r"^SPS: (\d+)", out.stdout, re.MULTILINE)]
    if out.returncode or len(sps) < 2:
        last_line = (out.stderr.strip().splitlines() or ["no output"])[-1]
        sys.exit(f"error: CleanRL's {script.name} failed under {args.cleanrl_python}: {last_line}")
    # It prints its SPS since the start after every iteration: the k-th is k·batch_size / elapsed.
    first, last = (k * batch_size / sps[k - 1] for k in (1, len(sps)))
    return batch_size * (len(sps) - 1) / (last - first)


def compile_seconds(module, env_id: str, steps: int) -> tuple[float, float]:
    """Extra wall time of a `steps`-long training run with --compile over one without, each in a fresh
    process (imports, compile and all): with inductor's cache empty, then with it warm."""

    def wall(cache_dir: str, *flags: str) -> float:
        with tempfile.TemporaryDirectory() as out:
            command = [sys.executable, module.__file__, "--env-id", env_id, "--total-timesteps", str(steps),
                       "--guidance", "1.1", "--output-dir", out, *flags]  # fmt: skip
            start = time.perf_counter()
            cache = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": cache_dir}
            subprocess.run(command, check=True, capture_output=True, env=cache)
            return time.perf_counter() - start

    with tempfile.TemporaryDirectory() as cache_dir:
        eager = min(wall(cache_dir), wall(cache_dir))
        cold, warm = wall(cache_dir, "--compile"), wall(cache_dir, "--compile")
    return cold - eager, warm - eager


def steady_sps(turns: list[float], batch_size: int) -> float:
    """Steps per second of a run's iterations after its first (turn 0 is the setup, turn 1 the first
    iteration, where --compile compiles)."""
    return batch_size * len(turns[2:]) / sum(turns[2:])


def paired_ratio(numerators: list[float], denominators: list[float]) -> float:
    """Median over repeats of the ratio within each repeat."""
    return float(np.median(np.array(numerators) / np.array(denominators)))


def overhead_with_interval(base: np.ndarray, treated: np.ndarray, resamples: int = 10_000) -> str:
    """sum(treated)/sum(base) - 1 over paired durations, with a 95% bootstrap interval that resamples
    the pairs."""
    picks = np.random.default_rng(0).integers(0, len(base), (resamples, len(base)))
    low, high = np.percentile(treated[picks].sum(1) / base[picks].sum(1) - 1, [2.5, 97.5])
    return f"{treated.sum() / base.sum() - 1:+.1%} ({low:+.1%} to {high:+.1%})"


def sweep_checkpoint(given: dict[str, Path], env_id: str, module, args, tmp: str) -> Path:
    """The checkpoint given for `env_id`, or one trained here with `args`."""
    if env_id in given:
        return given[env_id]
    args.output_dir = tmp
    return latest_checkpoint(train_in_process(module, args))


def checkpoints_by_env(paths) -> dict[str, Path]:
    """{env_id: path} of the given checkpoints; exits with one line of error on one that does not load."""
    by_env = {}
    for path in map(Path, paths):
        try:
            by_env[load_any_checkpoint(path)[1]["env_id"]] = path
        except ValueError as e:
            sys.exit(f"error: --sweep-checkpoints {path}: {str(e).splitlines()[0]}")
    return by_env


def sweep_rates(checkpoint: Path, gammas, episodes: int) -> tuple[float, float]:
    agent, ckpt = load_any_checkpoint(checkpoint)
    policy = GuidedPolicy(agent, ckpt)
    start = time.perf_counter()  # the sweep's cells: one per γ, its episodes stepping together (evaluate_cell)
    steps = sum(int(evaluate_cell(policy, ckpt, gamma, episodes, 10_000, False)["length"].sum()) for gamma in gammas)
    batched = steps / (time.perf_counter() - start)
    start, sequential_steps = time.perf_counter(), 0  # the reference: each episode k a cell of its own, one at a time
    for gamma in gammas:
        for k in range(episodes):
            sequential_steps += int(evaluate_cell(policy, ckpt, gamma, 1, 10_000 + k, False)["length"].sum())
    sequential = sequential_steps / (time.perf_counter() - start)
    return batched, sequential


def main() -> None:
    args = tyro.cli(Args)
    if args.cleanrl_dir:
        missing = [name for name in CLEANRL_SCRIPTS.values() if not Path(args.cleanrl_dir, name).is_file()]
        if missing:
            sys.exit(f"error: --cleanrl-dir {args.cleanrl_dir} has no {' or '.join(missing)}")
    given_checkpoints = checkpoints_by_env(args.sweep_checkpoints)
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)  # its first call imports a lot; keep that out of the timings
    rows = []

    cartpole = lambda g, compiled=False: ppo_pgg_discrete.Args(
        env_id="CartPole-v1", total_timesteps=args.cartpole_steps, guidance=g, compile=compiled
    )
    hopper = lambda g, compiled=False: ppo_pgg_continuous.Args(
        env_id="Hopper-v4", total_timesteps=args.hopper_steps, guidance=g, compile=compiled
    )
    configs = [("CartPole-v1", ppo_pgg_discrete, cartpole), ("Hopper-v4", ppo_pgg_continuous, hopper)]
    variants = [(1.0, False), (1.1, False), (1.0, True), (1.1, True)]  # (guidance, --compile)
    sps = {(env, *v): [] for env, _, _ in configs for v in variants}
    cleanrl_runs = {env: [] for env, _, _ in configs}
    # Paired across the two guidances, iteration by iteration and run by run:
    iteration_times = {(env, *v): [] for env, _, _ in configs for v in variants}
    update_times = {(env, *v): [] for env, _, _ in configs for v in variants}
    for repeat in range(args.repeats):
        for env_id, module, make_args in configs:
            # Alternate the order: back-to-back runs in one process are not equally fast (the second
            # was up to 20% slower here), which would bias the PGG overhead.
            order = variants if repeat % 2 == 0 else variants[::-1]
            if args.cleanrl_dir and repeat % 2:
                cleanrl_runs[env_id].append(cleanrl_sps(args, env_id, make_args(1.0)))
            runs = [make_args(*v) for v in order]
            for v, run, timed in zip(order, runs, interleaved_training(module, runs)):
                sps[(env_id, *v)].append(steady_sps(timed["turns"], run.num_envs * run.num_steps))
                iteration_times[(env_id, *v)] += timed["turns"][
                    2:-1
                ]  # not the setup, the first iteration, the final checkpoint
                update_times[(env_id, *v)] += timed["updates"][1:]
            if args.cleanrl_dir and not repeat % 2:
                cleanrl_runs[env_id].append(cleanrl_sps(args, env_id, make_args(1.0)))

    for env_id, module, make_args in configs:
        train_args = make_args(1.0)
        single, vector = env_rates(module, env_id, train_args)
        batch_size = train_args.num_envs * train_args.num_steps
        cold, warm = compile_seconds(module, env_id, 2 * batch_size)
        rows += [
            (env_id, "raw env, one gym.make env (steps/s)", f"{single:,.0f}"),
            (env_id, f"raw env, training vector env of {train_args.num_envs} (steps/s)", f"{vector:,.0f}"),
        ]
        for compiled in (False, True):
            flag = ", --compile" if compiled else ""
            ppo, pgg = max(sps[(env_id, 1.0, compiled)]), max(sps[(env_id, 1.1, compiled)])
            pgg_cost = paired_ratio(sps[(env_id, 1.0, compiled)], sps[(env_id, 1.1, compiled)])
            iteration_cost, update_cost = (
                overhead_with_interval(*(np.array(times[(env_id, g, compiled)]) for g in (1.0, 1.1)))
                for times in (iteration_times, update_times)
            )
            iterations, updates = (
                len(iteration_times[(env_id, 1.0, compiled)]),
                len(update_times[(env_id, 1.0, compiled)]),
            )
            if args.cleanrl_dir:
                speedup = f"{paired_ratio(sps[(env_id, 1.1, compiled)], cleanrl_runs[env_id]):.2f}x (same run)"
            else:
                low, high = CLEANRL_SPS[env_id]
                speedup = f"{pgg / high:.2f}x - {pgg / low:.2f}x (against quoted SPS)"
            rows += [
                (env_id, f"training SPS, guidance 1.0 (PPO){flag}", f"{ppo:,.0f}"),
                (env_id, f"training SPS, guidance 1.1 (PGG){flag}", f"{pgg:,.0f}"),
                (
                    env_id,
                    f"PGG time overhead{flag}, whole runs: median of SPS(1.0)/SPS(1.1) - 1",
                    f"{pgg_cost - 1:+.1%}",
                ),
                (env_id, f"PGG time overhead{flag}, {iterations} paired iterations (95% CI)", iteration_cost),
                (env_id, f"PGG time overhead{flag}, {updates} paired PPO updates (95% CI)", update_cost),
                (env_id, f"training speed-up over CleanRL, PGG at 1.1{flag}", speedup),
                (env_id, f"training SPS / raw vector env rate, PGG at 1.1{flag}", f"{pgg / vector:.2f}"),
            ]
        eager_pgg, compiled_pgg = (sps[(env_id, 1.1, compiled)] for compiled in (False, True))
        saved_per_step = 1 / max(eager_pgg) - 1 / max(compiled_pgg)
        breakeven = "never" if saved_per_step <= 0 else " / ".join(f"{t / saved_per_step:,.0f}" for t in (cold, warm))
        rows += [
            (env_id, "--compile speed-up over eager, PGG at 1.1", f"{paired_ratio(compiled_pgg, eager_pgg):.2f}x"),
            (env_id, "--compile one-off cost, inductor cache cold / warm (s)", f"{cold:.1f} / {warm:.1f}"),
            (env_id, "--compile pays back after (steps), cache cold / warm", breakeven),
        ]
        if args.cleanrl_dir:
            rows.append((env_id, "CleanRL's script, same run (SPS)", f"{max(cleanrl_runs[env_id]):,.0f}"))
        with tempfile.TemporaryDirectory() as tmp:
            quick = make_args(1.1)
            quick.total_timesteps = 4 * quick.num_envs * quick.num_steps
            checkpoint = sweep_checkpoint(given_checkpoints, env_id, module, quick, tmp)
            gammas = DEFAULT_GAMMAS["discrete" if module is ppo_pgg_discrete else "continuous"]
            batched, sequential = sweep_rates(checkpoint, gammas, args.sweep_episodes)
        rows += [
            (env_id, "sweep, batched evaluator (env steps/s)", f"{batched:,.0f}"),
            (env_id, "sweep, sequential one-env reference (env steps/s)", f"{sequential:,.0f}"),
            (env_id, "sweep speed-up, batched / sequential", f"{batched / sequential:.1f}x"),
            (env_id, "sweep rate / raw one-env stepping rate", f"{batched / single:.2f}"),
        ]
    width = max(len(r[1]) for r in rows)
    print(f"torch {torch.__version__}, numpy {np.__version__}, {args.repeats} repeat(s)")
    for env_id, what, value in rows:
        print(f"{env_id:12s} {what:{width}s} {value}")
    for (env_id, guidance, compiled), values in sps.items():
        print(
            f"{env_id:12s} SPS per repeat, {guidance}{' --compile' if compiled else ''}: "
            + ", ".join(f"{v:,.0f}" for v in values)
        )
    for env_id, values in cleanrl_runs.items():
        if values:
            print(f"{env_id:12s} SPS per repeat, cleanrl: " + ", ".join(f"{v:,.0f}" for v in values))


if __name__ == "__main__":
    main()
