"""The action distributions of the two training scripts and the guided mix of their parameters, once for both.

Each script's `guided_policy` (the one place a fork edits to change the distribution) builds one of these from the
two branches and γ; `guide` is the mix of their parameters that it calls. Each class computes on torch tensors (the
loss, the diagnostics) or numpy arrays (the rollouts, `act`) alike, with the arithmetic the tables' runs used. A fork
with another distribution (a squashed Gaussian, a Beta) writes its class in its script, with these methods: mode,
sample and sample_log_prob of noise, log_prob, entropy, kl, as_torch."""

import math

import numpy as np
import torch
from torch.distributions import Normal, kl_divergence

from pgg_utils.fast import standard_gumbel

LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)


def guide(cond, null, guidance):
    """The guided branch (1-γ)·null + γ·cond, the one place it is computed. For torch tensors (updates):
    torch.lerp(null, cond, γ), one op in place of three with their backward, which computes the same
    mixture as cond - (1-γ)·(cond - null) for γ >= 0.5 (the same up to the last bit). For numpy arrays
    (rollouts, `act`, the sweep): that formula in float32, its two weights rounded to float32 from
    double; `guidance` a number or one per row of `cond`."""
    if isinstance(cond, torch.Tensor):
        return torch.lerp(null, cond, guidance)
    guidance = np.asarray(guidance, dtype=np.float64)[..., None]  # a column, for one per row
    return np.asarray(1.0 - guidance, np.float32) * null + np.asarray(guidance, np.float32) * cond


class Gaussian:
    """A diagonal Gaussian over actions, of torch tensors (the loss, the diagnostics) or numpy arrays
    (rollouts, `act`): `mean` (B, action_dim); `logstd` and `std` = exp(logstd) broadcast against it,
    `std` passed where the caller computed it (its bits are the caller's exp). The formulas are
    torch.distributions.Normal's, summed over the action dimensions, written as the tables' runs
    computed them (tests/test_equivalence.py holds them to Normal's)."""

    def __init__(self, mean, logstd=None, std=None):
        self.mean, self._logstd, self._std = mean, logstd, std

    @property
    def logstd(self):
        if self._logstd is None:
            self._logstd = torch.log(self._std) if torch.is_tensor(self._std) else np.log(self._std)
        return self._logstd

    @property
    def std(self):
        if self._std is None:
            self._std = torch.exp(self._logstd) if torch.is_tensor(self._logstd) else np.exp(self._logstd)
        return self._std

    def mode(self):
        return self.mean

    def sample(self, noise):
        """The sample of standard normal `noise` (shaped like the actions)."""
        return self.mean + self.std * noise

    def sample_log_prob(self, noise):
        """(sample, its log-probability); log N(mean + σ·noise; mean, σ) is -noise²/2 - log σ - log √(2π)."""
        return self.sample(noise), (-0.5 * (noise * noise) - self.logstd - LOG_SQRT_2PI).sum(-1)

    def log_prob(self, actions: torch.Tensor) -> torch.Tensor:
        return (-0.5 * ((actions - self.mean) * torch.exp(-self.logstd)).square() - self.logstd - LOG_SQRT_2PI).sum(-1)

    def entropy(self):
        return (0.5 + LOG_SQRT_2PI + self.logstd).sum(-1)

    def kl(self, other: "Gaussian"):
        """KL(self || other), torch. With one σ, ½ Σ ((mean - other.mean)/σ)²."""
        if self.logstd is other.logstd:
            return 0.5 * ((self.mean - other.mean) * torch.exp(-other.logstd)).square().sum(-1)
        return kl_divergence(Normal(self.mean, self.std), Normal(other.mean, other.std)).sum(-1)

    def as_torch(self) -> "Gaussian":
        return Gaussian(*(torch.from_numpy(np.ascontiguousarray(x)) for x in (self.mean, self.logstd, self.std)))


class Categorical:
    """A categorical distribution over actions from `logits` (..., n_actions), of torch tensors (the loss,
    the diagnostics) or numpy arrays (rollouts, `act`), with the arithmetic the tables' runs used
    (tests/test_equivalence.py holds it to torch.distributions.Categorical). Its log-softmax is computed
    once: the loss's log-probabilities and entropy share one node of the graph. Samples by the Gumbel-max
    trick: argmax(logits + standard Gumbel noise)."""

    def __init__(self, logits):
        self.logits, self._log_softmax = logits, None

    @property
    def log_softmax(self) -> torch.Tensor:
        if self._log_softmax is None:
            self._log_softmax = self.logits.log_softmax(-1)
        return self._log_softmax

    def mode(self):
        return self.logits.argmax(-1)

    def sample(self, gumbel):
        return (self.logits + gumbel).argmax(-1)

    def sample_log_prob(self, gumbel):
        actions = self.sample(gumbel)
        return actions, self.log_prob(actions)

    def log_prob(self, actions):
        if torch.is_tensor(self.logits):
            return self.log_softmax.gather(-1, actions.unsqueeze(-1)).squeeze(-1)
        # In numpy, the log-softmax of the given actions only: a third of the cost of the full one.
        shifted = self.logits - self.logits.max(-1, keepdims=True)
        return shifted[np.arange(len(actions)), actions] - np.log(np.exp(shifted).sum(-1))

    def entropy(self) -> torch.Tensor:
        return -(self.log_softmax.exp() * self.log_softmax).sum(-1)

    def kl(self, other: "Categorical") -> torch.Tensor:
        """KL(self || other), torch."""
        return (self.log_softmax.exp() * (self.log_softmax - other.log_softmax)).sum(-1)

    def as_torch(self) -> "Categorical":
        return Categorical(torch.from_numpy(np.ascontiguousarray(self.logits)))


def gumbel_noise(*shape: int) -> np.ndarray:
    """Standard Gumbel noise, float32, from torch's generator (Gumbel-max sampling: fast.standard_gumbel)."""
    return standard_gumbel(torch.rand(*shape).numpy())
