"""What the live checks of the policy paths cost a training run: the probe before every checkpoint (`path_error` on
the trained agent) against one training iteration (rollout, GAE, update) of the same run. The ratio check of every
update costs nothing to measure: it reads the first minibatch's approx_kl, which ppo_update computes anyway.

    python -m benchmarks.bench_live_checks            # CartPole-v1 and Hopper-v4 at γ_train 1.1, 5 rounds each

Each round times one iteration and then the probe, in one process with one torch thread, so the ratio holds on a
loaded machine; it prints the median and range of the probe's share of an iteration, and its share of a run (a probe
per --checkpoint-interval steps, 200k by default)."""

import time
from dataclasses import asdict, dataclass
from statistics import median

import numpy as np
import torch
import tyro

import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import tasks
from pgg_utils.policy import path_error, probe_observations


@dataclass
class Args:
    rounds: int = 5
    """training iterations timed per task, each followed by the checkpoint probe"""


def bench(module, env_id: str, rounds: int) -> None:
    torch.set_num_threads(1)
    args = module.Args(env_id=env_id, guidance=1.1)
    continuous = module is ppo_pgg_continuous
    wrap = (lambda env: module.training_env(env, args.discount, args.reward_clip)) if continuous else None
    envs = tasks.make_vector_env(module.make_env, env_id, args.num_envs, args.seed, wrap=wrap)
    shapes = tasks.checkpoint_shapes(module.make_env(env_id)())
    agent = module.make_agent(asdict(args), shapes)
    obs_dim = envs.single_observation_space.shape[0]
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    probe = probe_observations(envs.single_observation_space)
    if continuous:
        buf = module.Rollout.empty(args.num_steps, args.num_envs, obs_dim, shapes["action_dim"])
        noise = np.random.default_rng(1).standard_normal((len(probe), shapes["action_dim"])).astype(np.float32)
        normalise = agent.obs_norm.normalise
    else:
        buf = module.Rollout.empty(args.num_steps, args.num_envs, obs_dim)
        noise = -np.log(-np.log(np.random.default_rng(1).random((len(probe), shapes["n_actions"]), np.float32)))
        normalise = lambda raw: raw.astype(np.float32)
    raw, _ = envs.reset(seed=args.seed)
    next_obs = agent.obs_norm.observe(raw) if continuous else raw
    next_done = np.zeros(args.num_envs, dtype=np.float32)
    seconds = {"iteration": [], "checkpoint probe": []}
    for _ in range(rounds):
        start = time.perf_counter()
        policy = module.FastPolicy(agent, args.guidance)
        next_obs, next_done = module.collect_rollout(policy, envs, next_obs, next_done, buf, lambda *a: None, 0)
        advantages, returns = module.compute_gae(buf, policy.value(next_obs), next_done, args.discount, args.gae_lambda)
        module.ppo_update(agent, optimizer, buf, advantages, returns, args, args.guidance)
        done = time.perf_counter()
        path_error(module, agent, args, probe, normalise, noise)
        seconds["iteration"].append(done - start)
        seconds["checkpoint probe"].append(time.perf_counter() - done)
    shares = [probe / iteration for probe, iteration in zip(seconds["checkpoint probe"], seconds["iteration"])]
    iterations_per_checkpoint = args.checkpoint_interval / (args.num_envs * args.num_steps)
    print(f"{env_id}: median ms: " + ", ".join(f"{key} {1000 * median(values):.2f}" for key, values in seconds.items())
          + f"; the probe is {100 * median(shares):.2f}% of one iteration ({100 * min(shares):.2f}-"
          f"{100 * max(shares):.2f}), {100 * median(shares) / iterations_per_checkpoint:.4f}% of the iterations "
          f"between two checkpoints")  # fmt: skip
    envs.close()


def main() -> None:
    rounds = tyro.cli(Args).rounds
    bench(ppo_pgg_discrete, "CartPole-v1", rounds)
    bench(ppo_pgg_continuous, "Hopper-v4", rounds)


if __name__ == "__main__":
    main()
