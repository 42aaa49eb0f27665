"""A behaviour-cloned unconditional branch for any trained agent, without retraining: the null embedding
fitted by maximum likelihood to the actions of the agent's own episodes, the rest of the network frozen.
The result is a checkpoint like any other, swept like any other; it records the fit (`null_fit`), and
its configuration and the sweep's `null_branch` column name it (`null=bc`, `bc`), so it is never pooled
with the agent's learned or zero null.

    python -m pgg_utils.bc_null results/continuous/agents --steps 1000000 --output runs/bc_null
    python eval_gamma_sweep.py runs/bc_null --output runs/sweeps/bc_null

The episodes are the agent's own policy at γ = 1 (its conditional policy), sampled, from reset seeds
`episode_seed + k` (30000 and up by default: apart from the sweep's 10000 and the held-out sweep's
20000). Continuous: the Gaussian likelihood of the sampled (unclipped) actions under N(mu_null, σ), σ
the agent's; its maximum puts mu_null at the mean action over the visited states, as near as the
frozen actor can reach. Discrete: the categorical likelihood of the sampled actions under
softmax(logits_null): the action frequencies."""

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import tyro

from pgg_utils import checkpoints, evaluation, scripts
from pgg_utils.files import InputError, one_line_errors, write_atomic
from pgg_utils.identity import FITTED_NULL_SUFFIX, run_of

BC_FIT = "behaviour cloning"


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """run directories, roots to search for them, or checkpoint files"""
    output: str = "bc_null"
    """folder of the fitted checkpoints: <run>__bcnull/checkpoints/step_*.pt, <run> the source's run (identity.run_of)"""
    steps: tuple[int, ...] | None = None
    """only the checkpoints of these step marks; None: all"""
    episodes: int = 40
    """episodes of the agent's own policy to fit to (a pilot: 20 episodes put the fitted unconditional mean within 0.02-0.18 σ of 40's, results/beyond/bc_null/pilot.txt)"""
    episode_seed: int = 30_000
    """episode k resets with seed episode_seed + k, its action noise from that seed too"""
    fit_steps: int = 2000
    """Adam steps on the null embedding (full batch)"""
    learning_rate: float = 0.05
    """Adam's learning rate"""
    script: tuple[str, ...] = ()
    """training scripts to load with besides the repository's (as eval_gamma_sweep.py --script)"""


class OwnPolicy:
    """The agent's policy at γ = 1 as the sweep's episode loop acts with it (pgg_utils.evaluation.evaluate_cell, which
    takes it in place of the sweep's GuidedPolicy), sampled with noise of its own: episode k's from
    np.random.default_rng([episode_seed + k, 2]), in float64 (standard normal; discrete, Gumbel). It keeps each
    step's samples, continuous ones before clipping to the bounds (the policy's own samples)."""

    def __init__(self, agent, ckpt: dict, make_env):
        self.agent, self.kind, self.make_env, self.samples = agent, ckpt["action_space"], make_env, []

    def reset(self) -> None:
        if callable(reset := getattr(self.agent, "reset", None)):  # a recurrent actor starts from a fresh state
            reset()

    def noise(self, episode_seed: int, episode: int, horizon: int, action_size: int) -> np.ndarray:
        rng = np.random.default_rng([episode_seed + episode, 2])
        if self.kind == "discrete":
            return rng.gumbel(size=(horizon, action_size))
        return rng.standard_normal(size=(horizon, action_size))

    def act(self, obs: np.ndarray, guidance: np.ndarray, noise: np.ndarray, deterministic: bool) -> np.ndarray:
        with torch.no_grad():
            if self.kind == "discrete":
                sampled = (self.agent.acting_policy(obs.astype(np.float32), guidance).logits + noise).argmax(-1)
            else:
                sampled = self.agent.acting_policy(obs, guidance).sample(noise)
        self.samples.append(sampled)
        if self.kind == "discrete" or self.agent.action_bounds is None:
            return sampled
        return np.clip(sampled, *self.agent.action_bounds)

    def seen_actions(self, lengths: np.ndarray) -> np.ndarray:
        """The samples of the episodes that took each step (episode k takes steps 0 to lengths[k] - 1), step by
        step, in episode order within a step."""
        return np.concatenate([sampled[lengths > t] for t, sampled in enumerate(self.samples)])


def own_episodes(agent, ckpt: dict, make_env, episodes: int, episode_seed: int) -> np.ndarray:
    """The sampled actions of `episodes` episodes of the agent's policy at γ = 1, played by the sweep's episode
    loop (all stepping together); continuous actions before clipping to the bounds (the policy's own samples).
    ValueError (one line) where the task raises or returns a NaN or an infinity."""
    policy = OwnPolicy(agent, ckpt, make_env)
    try:
        lengths = evaluation.evaluate_cell(policy, ckpt, 1.0, episodes, episode_seed, False)["length"]
    except evaluation.EpisodeFault as e:
        raise ValueError(str(e)) from None
    return policy.seen_actions(lengths)


def reach(agent, kind: str, null: torch.Tensor, actions: np.ndarray) -> float:
    """How far the fitted unconditional branch lies from the likelihood's unconstrained maximum, which the
    frozen actor may not reach: continuous, the largest gap of its mean to the mean action, in units of σ;
    discrete, the largest gap of its probabilities to the action frequencies."""
    with torch.no_grad():
        if kind == "discrete":
            probabilities = torch.softmax(agent.actor(null[None])[0], -1).numpy()
            return float(
                np.abs(probabilities - np.bincount(actions, minlength=len(probabilities)) / len(actions)).max()
            )
        sigma = agent.actor_logstd.exp()[0].numpy()
        return float(np.abs((agent.actor_mean(null[None])[0].numpy() - actions.mean(0)) / sigma).max())


def fit_null(agent, kind: str, actions: np.ndarray, fit_steps: int, learning_rate: float) -> tuple[torch.Tensor, float]:
    """(the null embedding that maximises the likelihood of `actions` under pi(.|null), the final mean
    negative log-likelihood per action, constants included). Only the null embedding moves."""
    null = agent.null_obs.detach().clone().zero_().requires_grad_(True)
    optimizer = torch.optim.Adam([null], lr=learning_rate)
    trainable = [parameter for parameter in agent.parameters() if parameter.requires_grad]
    for parameter in trainable:  # the rest of the agent is frozen: no gradient is computed for it
        parameter.requires_grad_(False)
    if kind == "discrete":
        targets = torch.as_tensor(actions, dtype=torch.long)
        nll = lambda: torch.nn.functional.cross_entropy(agent.actor(null[None]).expand(len(targets), -1), targets)
    else:
        targets, log_std = torch.as_tensor(actions, dtype=torch.float32), agent.actor_logstd[0]
        constant = float(log_std.sum()) + 0.5 * math.log(2 * math.pi) * len(log_std)
        nll = lambda: (
            0.5 * ((targets - agent.actor_mean(null[None])) / log_std.exp()).square().sum(-1).mean() + constant
        )
    for _ in range(fit_steps):
        optimizer.zero_grad()
        loss = nll()
        loss.backward()
        optimizer.step()
    for parameter in trainable:
        parameter.requires_grad_(True)
    with torch.no_grad():
        return null.detach(), float(nll())


def fitted_checkpoint(path: Path, ckpt: dict, args: Args, given: tuple[Path, ...], run: str) -> dict:
    """The checkpoint `ckpt` (read from `path`) with its null embedding behaviour-cloned, and the fit
    recorded, as a checkpoint of the run `run`."""
    if ckpt.get("null_fit"):
        raise ValueError("already holds a fitted null branch")
    if ckpt["args"].get("null_dims") is not None:
        raise ValueError("its null embedding replaces some observation dimensions only (--null-dims): "
                         "its unconditional branch depends on the state, which this fit does not model")  # fmt: skip
    agent, module, _ = scripts.load_agent(ckpt, path, given)
    actions = own_episodes(agent, ckpt, module.make_env(ckpt["env_id"]), args.episodes, args.episode_seed)
    null, nll = fit_null(agent, ckpt["action_space"], actions, args.fit_steps, args.learning_rate)
    fit = {"method": BC_FIT, "episodes": args.episodes, "episode_seed": args.episode_seed, "actions": len(actions),
           "fit_steps": args.fit_steps, "learning_rate": args.learning_rate, "nll": nll,
           "reach": reach(agent, ckpt["action_space"], null, actions),
           "source": f"{run_of(ckpt, path)}/checkpoints/{Path(path).name}",
           "source_null_norm": float(ckpt["model"]["null_obs"].norm()),
           # the code, machine and stack that fitted it (`code` names the training's)
           "code": scripts.code_revision(Path(__file__)), "machine": checkpoints.machine(),
           "versions": checkpoints.package_versions()}  # fmt: skip
    agent = {key: value for key, value in ckpt.items() if key != "resume"}  # an agent to evaluate, not to resume
    return {**agent, "run": run, "model": {**ckpt["model"], "null_obs": null}, "null_fit": fit}


def argument_error(args: Args) -> str | None:
    """What is wrong with the arguments, in one line, or None."""
    if not args.paths:
        return "no run directories, roots or checkpoint files given (e.g. python -m pgg_utils.bc_null runs/)"
    for name in ("episodes", "fit_steps"):
        if getattr(args, name) <= 0:
            return f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}"
    if not (math.isfinite(args.learning_rate) and args.learning_rate > 0):
        return f"--learning-rate must be a finite number > 0, got {args.learning_rate}"
    if args.episode_seed < 0:
        return f"--episode-seed must be a non-negative integer (reset seeds), got {args.episode_seed}"
    return scripts.given_script_error(args.script)


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        if error := argument_error(args):
            raise InputError(error)
        torch.set_num_threads(1)
        given, written = tuple(Path(p).resolve() for p in args.script), 0
        for path in checkpoints.find_checkpoints(args.paths, args.steps):
            try:
                ckpt = checkpoints.read_checkpoint_file(path)
            except ValueError as e:
                print(f"skipped {path}: {e}", file=sys.stderr)
                continue
            run = run_of(ckpt, path) + FITTED_NULL_SUFFIX
            destination = Path(args.output) / run / "checkpoints" / path.name
            if destination.exists():
                print(f"{destination} exists; kept", file=sys.stderr)
                continue
            try:
                ckpt = fitted_checkpoint(path, ckpt, args, given, run)
            except scripts.ScriptError as e:  # no checkpoint of this script can be fitted: the user must say which
                raise InputError(f"{path}: {e}") from None
            except ValueError as e:
                print(f"skipped {path}: {e}", file=sys.stderr)
                continue
            write_atomic(destination, checkpoints.checkpoint_bytes(ckpt))
            fit = ckpt["null_fit"]
            print(f"{destination}: {fit['actions']} actions, NLL {fit['nll']:.4f}", file=sys.stderr)
            written += 1
        print(f"wrote {written} checkpoint(s) to {args.output}")


if __name__ == "__main__":
    main()
