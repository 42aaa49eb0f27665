"""Sweep the PGG guidance strength γ on saved checkpoints, without retraining.

    python eval_gamma_sweep.py runs/ --output sweeps/all
    python eval_gamma_sweep.py runs/discrete --gammas 1 2 5 --steps 100000 500000 --workers 2

Every checkpoint under the given run directories (or roots) is evaluated at each γ for `--episodes`
episodes. All episodes of all γ values of one checkpoint step together as one batch of environments
with one batched policy forward per step.

Reproducibility. Episode k of every cell starts from `env.reset(seed=eval_seed + k)` and draws its
action noise from its own stream, `np.random.default_rng([eval_seed + k, 1])`: the same episode seeds
and noise for every γ and every checkpoint (common random numbers). The default eval_seed, 10_000,
keeps evaluation seeds disjoint from the training scripts' (seed + env index, i.e. small integers).
Policy forwards always run on at least MIN_FORWARD_ROWS rows, because CPU BLAS rounds a 1-3 row
product differently from a larger one: an episode's actions never depend on how many other
episodes share its batch, so the batched sweep equals a sequential one-env evaluation exactly.

Outputs (in --output): cells/*.csv, one per finished (checkpoint, γ) cell, written atomically; a rerun
skips those cells, so an interrupted sweep loses only the cells in flight. Then episodes.csv (every
episode of the requested cells, sorted) and summary.csv (per env, variant, step and γ: mean over seeds
of the per-seed mean return, and its 95% confidence interval, see `mean_ci95`).
"""

import csv
import functools
import hashlib
import math
import multiprocessing
import os
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
import tyro
from scipy import stats

import ppo_pgg_continuous
import ppo_pgg_discrete

PAPER_GAMMAS = {
    "discrete": (1.0, 1.5, 2.0, 5.0, 10.0, 20.0),
    "continuous": (1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.5),
}
MIN_FORWARD_ROWS = 8
# Part of every cell's identity; raised when a fix changes what a cell evaluates to, so that a rerun
# recomputes cells from before it. 2: continuous actions clipped to the env's bounds.
EVALUATOR_REVISION = 2
EPISODE_COLUMNS = [
    "env_id", "variant", "run", "seed", "train_guidance", "cond_dropout", "step", "global_step",
    "eval_guidance", "policy", "null_branch", "episode", "episode_seed", "return", "length",
]  # fmt: skip
SUMMARY_COLUMNS = [
    "env_id", "variant", "train_guidance", "cond_dropout", "step", "eval_guidance", "policy", "null_branch",
    "n_seeds", "n_episodes", "mean", "ci95", "ci_low", "ci_high", "ci_method", "seed_means",
]  # fmt: skip


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """run directories, roots to search for them, or checkpoint files"""
    output: str = "sweep"
    """output directory (cells/, episodes.csv, summary.csv); reusing it resumes a sweep"""
    gammas: tuple[float, ...] | None = None
    """eval guidance strengths; default the paper's: discrete 1 1.5 2 5 10 20, continuous 1 1.05 ... 1.3 1.5"""
    episodes: int = 50
    """episodes per (checkpoint, γ) cell"""
    steps: tuple[int, ...] | None = None
    """only the checkpoints of these step marks (e.g. 100000 500000); default all"""
    eval_seed: int = 10_000
    """episode k resets with seed eval_seed + k; keep it away from training seeds"""
    deterministic: bool = False
    """control: act with the argmax / mean of the guided policy instead of sampling it"""
    uniform_null: bool = False
    """control (discrete only): a uniform unconditional branch instead of the learned one, making
    guidance plain temperature scaling of the conditional policy"""
    workers: int = 1
    """processes that evaluate checkpoints in parallel"""
    ci: Literal["t", "bootstrap"] = "t"
    """confidence interval over per-seed means: Student t, or a percentile bootstrap"""
    bootstrap_samples: int = 10_000
    """resamples for --ci bootstrap"""


class InputError(Exception):
    """Bad input: reported as one line, exit status 2."""


# --- checkpoints ----------------------------------------------------------------------------------


def load_any_checkpoint(path: Path):
    """(agent, checkpoint dict) from a file of either training script; ValueError if it is neither."""
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # a truncated or foreign file raises anything from pickle/zip internals
        raise ValueError(f"unreadable checkpoint: {type(e).__name__}: {e}") from None
    module = {"discrete": ppo_pgg_discrete, "continuous": ppo_pgg_continuous}.get(ckpt.get("action_space"))
    if module is None:
        raise ValueError("not a PGG checkpoint (no known action_space field)")
    return module.agent_from_checkpoint(ckpt, path), ckpt


def variant_label(train_guidance: float, cond_dropout: float) -> str:
    if cond_dropout == 0:
        return "ppo" if train_guidance == 1.0 else f"pgg_g{train_guidance:g}"
    return f"pgg_drop{cond_dropout:g}" if train_guidance == 1.0 else f"pgg_g{train_guidance:g}_drop{cond_dropout:g}"


def discover_checkpoints(paths, steps) -> list[Path]:
    found = []
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise InputError(f"no such file or directory: {raw}")
        matches = [path] if path.is_file() else sorted(path.rglob("checkpoints/step_*.pt"))
        if not matches:
            raise InputError(f"no checkpoints (checkpoints/step_*.pt) under {raw}")
        found.extend(matches)
    if steps is not None:
        wanted = {f"step_{s:09d}.pt" for s in steps}
        found = [p for p in found if p.name in wanted]
        if not found:
            raise InputError(f"no checkpoint at steps {list(steps)} under {list(paths)}")
    return sorted(set(found))


# --- the batched guided policy ---------------------------------------------------------------------


class GuidedPolicy:
    """The guided policy of one checkpoint, evaluated for a batch of raw observations with one
    guidance strength per row. The unconditional branch is computed once, here."""

    def __init__(self, agent, ckpt: dict, uniform_null: bool = False):
        self.agent, self.kind = agent, ckpt["action_space"]
        with torch.no_grad():
            if self.kind == "discrete":
                learned = agent.unconditional_logits()
                self.null = torch.zeros_like(learned) if uniform_null else learned
            else:
                self.null = agent.unconditional_mean()
                self.std = agent.actor_logstd.exp()[0]
                # The environment's own bounds, which training clipped actions to. Not the checkpoint's
                # copy: checkpoints saved before 2026-11-22 hold ClipAction's ±inf there, and MuJoCo
                # tasks charge their control cost on the action as given.
                probe = make_eval_env(ckpt)
                self.low = torch.as_tensor(probe.action_space.low, dtype=torch.float32)
                self.high = torch.as_tensor(probe.action_space.high, dtype=torch.float32)
                probe.close()

    @torch.no_grad()
    def guided(self, raw_obs: np.ndarray, guidance: np.ndarray) -> torch.Tensor:
        """Guided logits (discrete) or guided means (continuous), one row per observation."""
        rows = len(raw_obs)
        padded = np.concatenate([raw_obs, np.repeat(raw_obs[:1], max(0, MIN_FORWARD_ROWS - rows), 0)])
        if self.kind == "discrete":
            cond = self.agent.actor(torch.as_tensor(padded, dtype=torch.float32))[:rows]
        else:
            cond = self.agent.actor_mean(self.agent.obs_norm(padded))[:rows]
        coef_null = torch.as_tensor(1.0 - guidance, dtype=torch.float32).unsqueeze(-1)
        coef_cond = torch.as_tensor(guidance, dtype=torch.float32).unsqueeze(-1)
        return coef_null * self.null + coef_cond * cond

    def act(self, raw_obs: np.ndarray, guidance: np.ndarray, noise: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions for a batch; `noise` holds one uniform (discrete: per action) or standard normal
        (continuous: per action dimension) draw per row, used unless deterministic."""
        guided = self.guided(raw_obs, guidance)
        if self.kind == "discrete":
            if not deterministic:
                guided = guided - torch.log(-torch.log(torch.as_tensor(noise, dtype=torch.float32)))
            return guided.argmax(-1).numpy()
        if not deterministic:
            guided = guided + self.std * torch.as_tensor(noise, dtype=torch.float32)
        return torch.maximum(torch.minimum(guided, self.high), self.low).numpy()


def episode_noise(kind: str, eval_seed: int, episode: int, horizon: int, action_size: int) -> np.ndarray:
    """The action noise of one evaluation episode, (horizon, action_size); the same for every γ."""
    rng = np.random.default_rng([eval_seed + episode, 1])
    if kind == "discrete":
        return rng.uniform(np.finfo(np.float32).tiny, 1.0, size=(horizon, action_size))
    return rng.standard_normal(size=(horizon, action_size))


def make_eval_env(ckpt: dict):
    module = ppo_pgg_discrete if ckpt["action_space"] == "discrete" else ppo_pgg_continuous
    return module.make_env(ckpt["env_id"])()


def horizon_and_action_size(env, ckpt) -> tuple[int, int]:
    horizon = env.spec.max_episode_steps if env.spec and env.spec.max_episode_steps else 10_000
    size = ckpt["n_actions"] if ckpt["action_space"] == "discrete" else ckpt["action_dim"]
    return horizon, size


def evaluate_batched(policy: GuidedPolicy, ckpt, gammas, episodes, eval_seed, deterministic):
    """All episodes of all γ values together; returns (returns, lengths), each (len(gammas), episodes),
    and the number of environment steps taken."""
    n = len(gammas) * episodes
    envs = [make_eval_env(ckpt) for _ in range(n)]
    horizon, action_size = horizon_and_action_size(envs[0], ckpt)
    noise = np.stack([episode_noise(policy.kind, eval_seed, k, horizon, action_size) for k in range(episodes)])
    guidance = np.repeat(np.asarray(gammas, dtype=np.float64), episodes)
    episode_of = np.tile(np.arange(episodes), len(gammas))
    obs = np.stack([env.reset(seed=eval_seed + int(episode_of[i]))[0] for i, env in enumerate(envs)])
    returns, lengths = np.zeros(n), np.zeros(n, dtype=np.int64)
    active = np.arange(n)
    t = 0
    while active.size:
        actions = policy.act(obs[active], guidance[active], noise[episode_of[active], t], deterministic)
        still_running = []
        for i, action in zip(active, actions):
            obs[i], reward, terminated, truncated, _ = envs[i].step(action)
            returns[i] += reward
            lengths[i] += 1
            if not (terminated or truncated):
                still_running.append(i)
        active = np.asarray(still_running, dtype=np.int64)
        t += 1
    for env in envs:
        env.close()
    return returns.reshape(len(gammas), episodes), lengths.reshape(len(gammas), episodes), int(lengths.sum())


def evaluate_sequential(policy: GuidedPolicy, ckpt, gamma, episodes, eval_seed, deterministic):
    """Reference: one environment, one episode after another, one observation per forward.
    Same seeds and noise as evaluate_batched; used by the tests and the benchmark."""
    env = make_eval_env(ckpt)
    horizon, action_size = horizon_and_action_size(env, ckpt)
    returns, lengths = [], []
    for k in range(episodes):
        noise = episode_noise(policy.kind, eval_seed, k, horizon, action_size)
        obs, _ = env.reset(seed=eval_seed + k)
        total, t, done = 0.0, 0, False
        while not done:
            action = policy.act(obs[None], np.array([gamma]), noise[t : t + 1], deterministic)[0]
            obs, reward, terminated, truncated, _ = env.step(action)
            total, t, done = total + reward, t + 1, terminated or truncated
        returns.append(total)
        lengths.append(t)
    env.close()
    return np.array(returns), np.array(lengths)


# --- cells, resumption, output ---------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    checkpoint: Path
    gammas: tuple[float, ...]  # the γ values of this checkpoint whose cells are missing
    settings: tuple  # (episodes, eval_seed, deterministic, uniform_null)


def settings_of(args: Args) -> tuple:
    return (args.episodes, args.eval_seed, args.deterministic, args.uniform_null)


@functools.lru_cache(maxsize=None)
def content_digest(checkpoint: Path, size: int, mtime_ns: int) -> str:
    """sha1 of the file, read once per sweep however many γ cells ask; size and mtime are in the
    cache key only, so that a checkpoint rewritten during the process is read again."""
    return hashlib.sha1(checkpoint.read_bytes()).hexdigest()


def cell_path(output: Path, checkpoint: Path, gamma: float, settings: tuple) -> Path:
    """One file per (checkpoint, γ, settings). The checkpoint's bytes, not its path or timestamp, are
    its identity: a retrained run is never mistaken for the one evaluated before, and a run directory
    copied to another machine or folder keeps its finished cells."""
    stat = checkpoint.stat()
    content = content_digest(checkpoint.resolve(), stat.st_size, stat.st_mtime_ns)
    key = f"{content}|{gamma!r}|{settings!r}|{EVALUATOR_REVISION}"
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return output / "cells" / f"{checkpoint.parent.parent.name}__{checkpoint.stem}__g{gamma:g}__{digest}.csv"


def run_job(job: Job):
    """Evaluates the missing cells of one checkpoint; returns (job, {γ: rows}, env steps, error)."""
    torch.set_num_threads(1)
    episodes, eval_seed, deterministic, uniform_null = job.settings
    try:
        agent, ckpt = load_any_checkpoint(job.checkpoint)
    except Exception as e:
        return job, {}, 0, f"{job.checkpoint}: {e}"
    if uniform_null and ckpt["action_space"] != "discrete":
        return job, {}, 0, f"{job.checkpoint}: --uniform-null applies to discrete checkpoints only"
    policy = GuidedPolicy(agent, ckpt, uniform_null)
    returns, lengths, env_steps = evaluate_batched(policy, ckpt, job.gammas, episodes, eval_seed, deterministic)
    train_args = ckpt["args"]
    common = {
        "env_id": ckpt["env_id"],
        "variant": variant_label(train_args["guidance"], train_args["cond_dropout"]),
        "run": job.checkpoint.parent.parent.name,
        "seed": train_args["seed"],
        "train_guidance": train_args["guidance"],
        "cond_dropout": train_args["cond_dropout"],
        "step": ckpt["step_mark"],
        "global_step": ckpt["global_step"],
        "policy": "deterministic" if deterministic else "sample",
        "null_branch": "uniform" if uniform_null else "learned",
    }
    rows = {
        gamma: [
            {**common, "eval_guidance": gamma, "episode": k, "episode_seed": eval_seed + k,
             "return": float(returns[g, k]), "length": int(lengths[g, k])}
            for k in range(episodes)
        ]
        for g, gamma in enumerate(job.gammas)
    }  # fmt: skip
    return job, rows, env_steps, None


def write_csv_atomic(path: Path, columns: list[str], rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def mean_ci95(values, method: str = "t", bootstrap_samples: int = 10_000) -> tuple[float, float, float, float]:
    """(mean, half-width, low, high) of the 95% confidence interval of the mean of `values` (here:
    one mean return per training seed). "t": mean ± t_{0.975, n-1} · s / sqrt(n), s the sample standard
    deviation (ddof=1). "bootstrap": percentile interval of `bootstrap_samples` resampled means (fixed
    RNG seed), half-width = (high - low) / 2. With one value the interval is undefined (nan)."""
    values = np.asarray(values, dtype=np.float64)
    n, mean = len(values), float(np.mean(values))
    if n < 2:
        return mean, math.nan, math.nan, math.nan
    if method == "t":
        half = float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n))
        return mean, half, mean - half, mean + half
    resampled = np.random.default_rng(0).choice(values, size=(bootstrap_samples, n)).mean(1)
    low, high = np.percentile(resampled, [2.5, 97.5])
    return mean, float((high - low) / 2), float(low), float(high)


def summarise(rows: list[dict], method: str = "t", bootstrap_samples: int = 10_000) -> list[dict]:
    """One row per (env, variant, step, γ, policy, null branch): statistics over seeds of the per-seed
    mean episodic return."""
    per_seed = defaultdict(lambda: defaultdict(list))
    for row in rows:
        key = tuple(str(row[c]) for c in SUMMARY_COLUMNS[:8])
        per_seed[key][str(row["seed"])].append(float(row["return"]))
    out = []
    for key in sorted(per_seed, key=lambda k: (k[0], k[1], int(k[4]), float(k[5]), k[6], k[7])):
        seed_means = [float(np.mean(v)) for _, v in sorted(per_seed[key].items())]
        mean, half, low, high = mean_ci95(seed_means, method, bootstrap_samples)
        out.append({
            **dict(zip(SUMMARY_COLUMNS[:8], key)),
            "n_seeds": len(seed_means), "n_episodes": sum(len(v) for v in per_seed[key].values()),
            "mean": round(mean, 4), "ci95": round(half, 4), "ci_low": round(low, 4), "ci_high": round(high, 4),
            "ci_method": method, "seed_means": ";".join(f"{m:.4f}" for m in seed_means),
        })  # fmt: skip
    return out


def episode_sort_key(row: dict):
    return (row["env_id"], row["variant"], row["run"], int(row["step"]), float(row["eval_guidance"]),
            row["policy"], row["null_branch"], int(row["episode"]))  # fmt: skip


def format_duration(seconds: float) -> str:
    seconds = int(seconds)
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m" if seconds >= 3600 else f"{seconds // 60}m{seconds % 60:02d}s"


def check_args(args: Args) -> None:
    if args.gammas is not None and not all(math.isfinite(g) for g in args.gammas):
        raise InputError(f"--gammas must be finite numbers, got {list(args.gammas)}")
    if args.episodes <= 0 or args.workers <= 0 or args.bootstrap_samples <= 0:
        raise InputError("--episodes, --workers and --bootstrap-samples must be positive")


def sweep(args: Args) -> Path:
    """Runs (or resumes) the sweep; returns the output directory."""
    check_args(args)
    output = Path(args.output)
    checkpoints = discover_checkpoints(args.paths, args.steps)
    settings = settings_of(args)
    skipped, jobs, wanted_cells = [], [], []
    for checkpoint in checkpoints:
        try:
            kind = torch.load(checkpoint, map_location="cpu", weights_only=True)["action_space"]
            gammas = args.gammas if args.gammas is not None else PAPER_GAMMAS[kind]
        except Exception as e:
            skipped.append(f"{checkpoint}: unreadable or not a PGG checkpoint ({type(e).__name__})")
            continue
        cells = {gamma: cell_path(output, checkpoint, gamma, settings) for gamma in dict.fromkeys(gammas)}
        wanted_cells.extend(cells.values())
        missing = tuple(g for g, path in cells.items() if not path.exists())
        if missing:
            jobs.append(Job(checkpoint, missing, settings))

    total_cells = sum(len(job.gammas) for job in jobs)
    print(f"{len(checkpoints)} checkpoints, {len(wanted_cells)} cells, {len(wanted_cells) - total_cells} already done", file=sys.stderr)
    done_cells, env_steps, start = 0, 0, time.time()
    pool = multiprocessing.get_context("fork").Pool(args.workers) if args.workers > 1 else None
    try:
        results = pool.imap_unordered(run_job, jobs) if pool else map(run_job, jobs)
        for job, rows, steps, error in results:
            if error:
                skipped.append(error)
                total_cells -= len(job.gammas)
                continue
            for gamma, cell_rows in rows.items():
                write_csv_atomic(cell_path(output, job.checkpoint, gamma, settings), EPISODE_COLUMNS, cell_rows)
            done_cells += len(rows)
            env_steps += steps
            elapsed = time.time() - start
            eta = elapsed / done_cells * (total_cells - done_cells)
            print(f"[{done_cells}/{total_cells} cells] {env_steps / elapsed:,.0f} env steps/s, "
                  f"elapsed {format_duration(elapsed)}, ETA {format_duration(eta)}", file=sys.stderr, flush=True)  # fmt: skip
    finally:
        if pool:
            pool.close()
            pool.join()

    rows = [row for path in wanted_cells if path.exists() for row in read_csv(path)]
    rows.sort(key=episode_sort_key)
    write_csv_atomic(output / "episodes.csv", EPISODE_COLUMNS, rows)
    summary = summarise(rows, args.ci, args.bootstrap_samples)
    write_csv_atomic(output / "summary.csv", SUMMARY_COLUMNS, summary)
    write_csv_atomic(output / "skipped.csv", ["reason"], [{"reason": s} for s in skipped])
    for reason in skipped:
        print(f"skipped {reason}", file=sys.stderr)
    print(f"wrote {output / 'episodes.csv'} ({len(rows)} episodes), {output / 'summary.csv'} ({len(summary)} rows)"
          + (f"; skipped {len(skipped)} checkpoint(s), listed in {output / 'skipped.csv'}" if skipped else ""))  # fmt: skip
    if not rows:
        raise InputError("no checkpoint could be evaluated")
    return output


def main() -> None:
    args = tyro.cli(Args)
    try:
        sweep(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
