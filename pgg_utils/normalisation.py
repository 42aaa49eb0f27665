"""The continuous script's observation and reward processing, CleanRL's per-sub-env wrappers at a fraction of their
cost: the reward scaling (NormalizeClipReward, on each sub-env) and the observation statistics that live inside the
agent (RunningObsNorm, the one normaliser), so that every checkpoint carries them. The same float64 operations in the same order as
gymnasium's, the same bits (tests/test_continuous.py)."""

import math

import gymnasium as gym
import numpy as np
import torch
from torch import nn


class NormalizeClipReward(gym.Wrapper):
    """gymnasium's NormalizeReward followed by ClipReward, the reward scaling CleanRL puts on each
    sub-env: rewards are divided by the running standard deviation of the discounted return (which
    a termination resets and a truncation does not), then clipped. The same float64 operations in
    the same order on Python floats, the same bits (tests/test_continuous.py) at a ninth of the cost."""

    def __init__(self, env: gym.Env, discount: float, clip: float, epsilon: float = 1e-8):
        super().__init__(env)
        self.discount, self.clip, self.epsilon = discount, clip, epsilon
        self.discounted_return, self.return_mean, self.return_var, self.return_count = 0.0, 0.0, 1.0, 1e-4

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.discounted_return = self.discounted_return * self.discount * (1 - terminated) + float(reward)
        # gymnasium's RunningMeanStd update with a batch of one (mean: the return, variance: 0)
        delta = self.discounted_return - self.return_mean
        total = self.return_count + 1
        self.return_mean += delta / total
        self.return_var = (self.return_var * self.return_count + delta * delta * self.return_count / total) / total
        self.return_count = total
        scaled = reward / math.sqrt(self.return_var + self.epsilon)
        return obs, min(max(scaled, -self.clip), self.clip), terminated, truncated, info


def update_running_moments(mean: np.ndarray, var: np.ndarray, count: np.ndarray, batch: np.ndarray) -> None:
    """gymnasium's RunningMeanStd update, in place on float64 arrays (`count` 0-d), with the same
    operations in the same order, at half its cost."""
    batch_count = batch.shape[0]
    batch_mean = batch.sum(0) / batch_count
    batch_var = np.square(batch - batch_mean).sum(0) / batch_count
    delta = batch_mean - mean
    total = count + batch_count
    m2 = var * count + batch_var * batch_count + np.square(delta) * count * batch_count / total
    mean += delta * batch_count / total
    var[:] = m2 / total
    count[...] = total


def normalise_obs(raw_obs, mean: np.ndarray, var: np.ndarray, epsilon: float, clip: float) -> np.ndarray:
    """Normalised, clipped float32 observations from raw ones (array-like, (B, obs_dim))."""
    normalised = (np.asarray(raw_obs, dtype=np.float64) - mean) / np.sqrt(var + epsilon)
    return np.minimum(np.maximum(normalised, -clip), clip).astype(np.float32)  # np.clip costs twice as much


class RunningObsNorm(nn.Module):
    """Running mean/variance of observations, as gymnasium's NormalizeObservation computes them, kept
    as buffers so that they are saved in the state dict. Only training rollouts update them, with the
    observations CleanRL's per-sub-env NormalizeObservation sees, in its order: every observation that
    a reset or a step returns, an episode's last one included (`collect_rollout`). Evaluation reads
    them frozen. With several sub-envs the statistics are pooled over them (CleanRL keeps one set per
    sub-env, which no single checkpoint could carry). The one normaliser: the rollouts, `act` and the
    sweep all call this object's methods, so a subclass (another normaliser, none) changes all of them."""

    def __init__(self, obs_dim: int, clip: float, epsilon: float = 1e-8):
        super().__init__()
        self.clip, self.epsilon = clip, epsilon
        self.register_buffer("mean", torch.zeros(obs_dim, dtype=torch.float64))
        self.register_buffer("var", torch.ones(obs_dim, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

    def statistics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Numpy views of (mean, var, count). Cached: a buffer's `.numpy()` on every rollout step cost as much as the
        update itself. The views follow load_state_dict's in-place copies; a buffer replaced by another tensor (`to`,
        `load_state_dict(assign=True)`) or a copy of the module (its cache is not copied) makes them anew."""
        buffers = (self._buffers["mean"], self._buffers["var"], self._buffers["count"])
        cached = self.__dict__.get("_views")
        if cached is None or any(held is not buffer for held, buffer in zip(cached[0], buffers)):
            cached = self.__dict__["_views"] = (buffers, tuple(buffer.numpy() for buffer in buffers))
        return cached[1]

    def __getstate__(self):
        return {key: value for key, value in self.__dict__.items() if key != "_views"}

    def normalise(self, raw_obs) -> np.ndarray:
        mean, var, _ = self.statistics()
        return normalise_obs(raw_obs, mean, var, self.epsilon, self.clip)

    def update(self, raw_obs: np.ndarray) -> None:
        """Adds the rows of `raw_obs` to the statistics, in place."""
        update_running_moments(*self.statistics(), raw_obs)

    def observe(self, raw_obs: np.ndarray) -> np.ndarray:
        """Adds `raw_obs` to the statistics and returns it normalised by them."""
        self.update(raw_obs)
        return self.normalise(raw_obs)

    def forward(self, raw_obs) -> torch.Tensor:
        return torch.from_numpy(self.normalise(raw_obs))
