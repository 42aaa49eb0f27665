"""One rollout's storage, once for both training scripts: `Rollout`, the buffers a script's `collect_rollout`
fills, and `flatten_rollout`, the one layout of rows its `minibatch_loss` reads."""

from dataclasses import dataclass

import torch


@dataclass
class Rollout:
    obs: torch.Tensor  # (num_steps, num_envs, obs_dim), as the actor took them (continuous: normalised then)
    actions: torch.Tensor  # (num_steps, num_envs, action_dim), before clipping; discrete: (num_steps, num_envs), int64
    logprobs: torch.Tensor  # (num_steps, num_envs), log pi_hat(a|s) at collection time
    rewards: torch.Tensor  # (num_steps, num_envs), as trained on (continuous: normalised and clipped)
    dones: torch.Tensor  # (num_steps, num_envs): 1 where obs[t] is the first observation of an episode
    values: torch.Tensor  # (num_steps, num_envs)

    @classmethod
    def empty(cls, num_steps: int, num_envs: int, obs_dim: int, action_dim: int | None = None) -> "Rollout":
        """Zeroed buffers; `action_dim` None: one integer action per step (a Discrete action space)."""
        zeros = lambda *shape: torch.zeros(shape)
        return cls(
            obs=zeros(num_steps, num_envs, obs_dim),
            actions=(
                torch.zeros((num_steps, num_envs), dtype=torch.long)
                if action_dim is None
                else zeros(num_steps, num_envs, action_dim)
            ),
            logprobs=zeros(num_steps, num_envs),
            rewards=zeros(num_steps, num_envs),
            dones=zeros(num_steps, num_envs),
            values=zeros(num_steps, num_envs),
        )


def flatten_rollout(buf: Rollout, advantages: torch.Tensor, returns: torch.Tensor) -> dict[str, torch.Tensor]:
    """The rollout as one batch of rows, the layout `minibatch_loss` reads."""
    return {
        "obs": buf.obs.reshape(-1, buf.obs.shape[-1]),
        "actions": buf.actions.reshape(-1, *buf.actions.shape[2:]),
        "logprobs": buf.logprobs.reshape(-1),
        "advantages": advantages.reshape(-1),
        "returns": returns.reshape(-1),
        "values": buf.values.reshape(-1),
    }
