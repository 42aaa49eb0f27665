"""What the live checks of the policy paths cost a training run: the ratio check before every update
(`pgg_utils.policy.first_ratio_error`, one minibatch's loss without gradient) and the probe before every checkpoint
(`path_error` on the trained agent), against one training iteration (rollout, GAE, update) of the same run.

    python -m benchmarks.bench_live_checks            # CartPole-v1 and Hopper-v4 at γ_train 1.1, 5 rounds each

Each round times one iteration and then each check, in one process with one torch thread, so the ratios hold on a
loaded machine; it prints the median and range of each check's share of an iteration, and the share of a run of the
default length (a ratio check per iteration, a probe per 200k steps)."""

import time
from dataclasses import asdict
from statistics import median

import numpy as np
import torch

import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils.policy import RATIO_CHECK_ROWS, first_ratio_error, path_error, probe_observations

ROUNDS = 5


def bench(module, env_id: str) -> None:
    torch.set_num_threads(1)
    args = module.Args(env_id=env_id, guidance=1.1)
    continuous = module is ppo_pgg_continuous
    if continuous:
        envs = module.make_vector_env(env_id, args.num_envs, args.seed, args.discount, args.reward_clip)
    else:
        envs = module.make_vector_env(env_id, args.num_envs, args.seed)
    shapes = module.checkpoint_shapes(module.make_env(env_id)())
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
    batch_size = args.num_envs * args.num_steps
    rows = torch.arange(0, batch_size, -(-batch_size // RATIO_CHECK_ROWS))  # the training scripts' rows
    shares = {"ratio check": [], "checkpoint probe": []}
    for _ in range(ROUNDS):
        start = time.perf_counter()
        policy = module.FastPolicy(agent, args.guidance)
        next_obs, next_done = module.collect_rollout(policy, envs, next_obs, next_done, buf, lambda *a: None, 0)
        advantages, returns = module.compute_gae(buf, policy.value(next_obs), next_done, args.discount, args.gae_lambda)
        checked = time.perf_counter()
        first_ratio_error(module, agent, module.flatten_rollout(buf, advantages, returns), rows, args.guidance, args)
        updated = time.perf_counter()
        module.ppo_update(agent, optimizer, buf, advantages, returns, args, args.guidance)
        done = time.perf_counter()
        path_error(module, agent, args, probe, normalise, noise)
        probed = time.perf_counter()
        iteration = (checked - start) + (done - updated)
        shares["ratio check"].append((updated - checked) / iteration)
        shares["checkpoint probe"].append((probed - done) / iteration)
    iterations_per_checkpoint = 200_000 / (args.num_envs * args.num_steps)
    ratio, probe_share = median(shares["ratio check"]), median(shares["checkpoint probe"])
    print(f"{env_id}: ratio check {100 * ratio:.3f}% of an iteration "
          f"({100 * min(shares['ratio check']):.3f}-{100 * max(shares['ratio check']):.3f}); checkpoint probe "
          f"{100 * probe_share:.2f}% of one iteration, {100 * probe_share / iterations_per_checkpoint:.3f}% of the "
          f"iterations between checkpoints; both: {100 * (ratio + probe_share / iterations_per_checkpoint):.3f}% "
          "of a run")  # fmt: skip
    envs.close()


if __name__ == "__main__":
    bench(ppo_pgg_discrete, "CartPole-v1")
    bench(ppo_pgg_continuous, "Hopper-v4")
