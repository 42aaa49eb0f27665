"""What holds for the guided policy whatever its distribution, once for both training scripts.

Each script defines its action distribution once (`guided_policy`: the two branches and γ in, a distribution out);
the loss, the rollouts' numpy copy and `Agent.act` all call it. This module holds what is not the algorithm:
- `numpy_policy`: the definition run on numpy branches (the rollouts', `act`'s), or, where it is written for torch
  alone, on their tensors (slower, the same definition; never a hand-written copy);
- `path_error`, the check of the paths against the definition: the rollouts, `act` and the loss agree with it on a
  probe batch at a γ other than 1, and the loss's first ratio is 1. When training starts it runs on a `randomised`
  copy of the agent (every parameter and buffer drawn at random, so a path that reads another parameter than the
  definition's disagrees), and at every checkpoint on the trained agent itself; `first_ratio_error` checks every
  update's first minibatch. A fork that edits one path and not the others stops in one line naming it;
- the null branch of an actor whose training mode couples rows or moves statistics (BatchNorm) or draws noise
  (Dropout): computed on its own, in eval mode (`branch_pass`, `null_pass`), so it needs no batch and moves nothing;
- `missing_methods`: the methods of `Agent` that the rest of the project calls;
- `guided_actions`, `Agent.act`'s body (its input checks, the noise's among them, sampling, clipping),
  `trained_parameters`, whether the null embedding trains, and `guidance_diagnostics`, what training logs of it."""

import copy
import math
import sys
from contextlib import contextmanager, nullcontext

import numpy as np
import torch
from torch import nn

from pgg_utils.arguments import acting_error
from pgg_utils.guidance import reads_parameter

# The γ of the start-up probe: not 1, where the null branch drops out of the guided policy.
PROBE_GUIDANCE = 1.3
PROBE_ROWS = 8
PROBE_RTOL, PROBE_ATOL = 1e-4, 1e-5
# The first minibatch's approx_kl, mean((r - 1) - log r) >= 0 per row, above which the ratio is not 1: on the probe
# batch, and (looser: float32 rounding of trained networks on a whole minibatch) on every update's first minibatch.
PROBE_MAX_KL = 1e-7
LIVE_MAX_KL = 1e-6
# Layers whose training mode mixes rows, moves statistics or draws noise.
MODE_DEPENDENT = (nn.modules.batchnorm._BatchNorm, nn.modules.dropout._DropoutNd)


class PathError(Exception):
    """A path of a training run (the rollouts, the loss, `act`) disagrees with the definition on the agent as it
    trains: the message, one line, names the path and what differs."""


def refuse(error: str, envs=None) -> None:
    """Stops training before it starts: one line, exit 2; `envs` closed first."""
    if envs is not None:
        envs.close()
    print(f"error: {error}", file=sys.stderr)
    sys.exit(2)


def mode_dependent(module: nn.Module) -> bool:
    return any(isinstance(layer, MODE_DEPENDENT) for layer in module.modules())


@contextmanager
def eval_mode(module: nn.Module):
    """`module` in eval mode inside the block, each submodule's own mode restored after it."""
    modes = [(layer, layer.training) for layer in module.modules()]
    module.eval()
    try:
        yield module
    finally:
        for layer, training in modes:
            layer.training = training


def frozen(network: nn.Module):
    """eval_mode for a network whose training mode couples rows, moves statistics or draws noise; for any other,
    nothing (its forward is the same in both modes, and a compiled loss then sees no mode switch)."""
    return eval_mode(network) if mode_dependent(network) else nullcontext(network)


def null_pass(network: nn.Module, null_in: torch.Tensor) -> torch.Tensor:
    """`network` on the null input alone, frozen: a BatchNorm takes one row and keeps its statistics."""
    with frozen(network):
        return network(null_in)


def branch_pass(network: nn.Module, obs: torch.Tensor, null_in: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(network(obs), network(null_in)). One pass where every layer computes each row alone (a separate one-row pass
    costs as much as the batch at this size, and can round differently); where a layer's training mode couples the
    rows or draws noise, the null input runs on its own in eval mode (`null_pass`)."""
    if mode_dependent(network):
        return network(obs), null_pass(network, null_in)
    return network(torch.cat([obs, null_in])).split([len(obs), len(null_in)])


def missing_methods(agent, required: dict[str, str]) -> str | None:
    """One line naming the first method of `required` ({name: who calls it}) that `agent` lacks, or None."""
    for name, caller in required.items():
        if not callable(getattr(agent, name, None)):
            return f"{type(agent).__name__} has no method {name}, which {caller} calls (see the Agent's docstring)"
    return None


def as_tensor(x):
    return x if torch.is_tensor(x) else torch.from_numpy(np.ascontiguousarray(x))


def as_array(x) -> np.ndarray:
    return x.detach().numpy() if torch.is_tensor(x) else np.asarray(x)


class TorchDefined:
    """A distribution that the definition computed in torch, used by numpy callers: noise and actions go in as
    numpy arrays, samples and log-probabilities come out as numpy arrays."""

    def __init__(self, distribution):
        self.distribution = distribution

    def __getattr__(self, name: str):  # its parameters (logits, mean), as arrays
        if name == "distribution":  # not yet set (a copy): no recursion
            raise AttributeError(name)
        return as_array(getattr(self.distribution, name))

    def sample(self, noise):
        return as_array(self.distribution.sample(as_tensor(noise)))

    def mode(self):
        return as_array(self.distribution.mode())

    def log_prob(self, actions):
        return as_array(self.distribution.log_prob(as_tensor(actions)))

    def sample_log_prob(self, noise):
        actions, log_probs = self.distribution.sample_log_prob(as_tensor(noise))
        return as_array(actions), as_array(log_probs)


def numpy_policy(definition, cond, null, guidance):
    """`definition(cond, null, guidance)` on numpy branches: computed in numpy where the definition is written with
    operations numpy has (the scripts' own), else on the branches' tensors, wrapped for numpy callers (TorchDefined).
    `guidance` a number or one per row."""
    try:
        return definition(cond, null, guidance)
    except (TypeError, AttributeError):  # a torch function given an array, or a tensor method asked of one
        column = np.asarray(guidance, dtype=np.float32)
        weight = float(column) if column.ndim == 0 else torch.from_numpy(column[:, None])
        return TorchDefined(definition(cond.as_torch(), null.as_torch(), weight))


def close(a, b) -> bool:
    a, b = as_array(a), as_array(b)
    if a.shape != b.shape:
        return False
    if np.issubdtype(a.dtype, np.integer) or np.issubdtype(b.dtype, np.integer):
        return np.array_equal(a, b)
    return np.allclose(a, b, rtol=PROBE_RTOL, atol=PROBE_ATOL)


def path_error(script, agent, args, raw_obs: np.ndarray, normalise, noise: np.ndarray) -> str | None:
    """The start-up check of a training script's policy paths on a probe batch (`raw_obs`, as the task gives it;
    `normalise` turns it into the actor's input; `noise` the rollouts' kind, one row per observation): one line
    naming the first path that disagrees with the definition (`agent.policy`, which calls `guided_policy`), or None.
    At γ = PROBE_GUIDANCE and at 1 (the loss then takes None, PPO's own pass):
    - the rollouts (`FastPolicy.act`) sample what the definition samples with the same noise, with its log-probs;
    - the loss (`minibatch_loss`) gives the rollout's actions the rollout's log-probs: the first ratio is 1;
    - `Agent.act` acts as the definition does, deterministic and sampled, one guidance per row as the sweep asks.
    Runs in eval mode and restores torch's RNG state: nothing trained, moved or drawn."""
    if error := missing_methods(agent, script.AGENT_METHODS):
        return error
    rng_state = torch.get_rng_state()
    try:
        with eval_mode(agent):
            for guidance, loss_guidance in ((PROBE_GUIDANCE, PROBE_GUIDANCE), (1.0, None)):
                if error := probe(script, agent, args, raw_obs, normalise, noise, guidance, loss_guidance):
                    return error
    except PathError as e:  # a path that cannot even run on the probe batch
        return str(e)
    finally:
        torch.set_rng_state(rng_state)
    return None


def running(path: str, call):
    """`call()`, or PathError naming `path` and the first line of what it raised: a path that cannot run on the
    probe batch (a distribution the fast path does not build, an observation of another shape) is one line."""
    try:
        return call()
    except Exception as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        raise PathError(f"{path} raised {type(e).__name__} on a probe batch: {first}") from e


def randomised(agent):
    """A copy of `agent` whose every floating-point parameter and buffer is drawn at random, from a generator of its
    own (no global RNG moves): the start-up probe runs on it, since a fresh agent (log-stds and the null embedding
    0, the observation statistics 0 and 1) hides a path that reads another parameter than the definition's.
    Parameters are normal, scaled by 1/√fan-in where they have one; buffers are drawn from [0.5, 1.5], a valid
    variance or count."""
    probed = copy.deepcopy(agent)
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for parameter in probed.parameters():
            scale = 1 / math.sqrt(parameter.shape[-1]) if parameter.dim() > 1 else 0.5
            parameter.copy_(scale * torch.randn(parameter.shape, generator=generator, dtype=parameter.dtype))
        for buffer in probed.buffers():
            if buffer.is_floating_point():
                buffer.copy_(0.5 + torch.rand(buffer.shape, generator=generator, dtype=buffer.dtype))
    return probed


def first_ratio_error(agent, stats: dict) -> None:
    """PathError where an update's first minibatch (`stats["losses/first_approx_kl"]`, ppo_update's), computed before
    any optimizer step on the parameters that acted, does not give the rollout's actions the rollout's
    log-probabilities (every ratio 1). Not for an agent whose training mode computes another function (BatchNorm's
    batch statistics, Dropout): its loss's policy is not the one that acted, by design. A non-finite KL is left to
    the run's own check of non-finite losses."""
    kl = stats["losses/first_approx_kl"]
    if not mode_dependent(agent) and math.isfinite(kl) and kl > LIVE_MAX_KL:
        raise PathError(
            f"the first minibatch's ratio is not 1 (approx_kl {kl:.3g} before any step): minibatch_loss's "
            "log-probabilities of the rollout's actions differ from the rollouts' own (FastPolicy.act)"
        )


def probe(script, agent, args, raw_obs, normalise, noise, guidance, loss_guidance) -> str | None:
    obs = normalise(raw_obs)
    at = f"at guidance {guidance:g} on a probe batch"
    with torch.no_grad():
        defined = running("Agent.policy (the loss's)", lambda: agent.policy(torch.from_numpy(obs), loss_guidance))
        actions, log_probs, _ = running("the rollouts (FastPolicy.act)",
                                        lambda: script.FastPolicy(agent, guidance).act(obs, noise))  # fmt: skip
        expected = defined.sample(torch.from_numpy(noise))
        if not close(actions, expected):
            return f"the rollouts' actions (FastPolicy.act) differ from guided_policy's samples {at}"
        if not close(log_probs, defined.log_prob(torch.from_numpy(actions))):
            return f"the rollouts' log-probabilities (FastPolicy.act) differ from guided_policy's {at}"
    rows = len(obs)
    batch = {"obs": torch.from_numpy(obs), "actions": torch.from_numpy(actions),
             "logprobs": torch.from_numpy(np.asarray(log_probs, np.float32)), "advantages": torch.ones(rows),
             "returns": torch.zeros(rows), "values": torch.zeros(rows)}  # fmt: skip
    _, stats = running("minibatch_loss", lambda: script.minibatch_loss(agent, batch, torch.arange(rows), None,
                                                                       loss_guidance, args))  # fmt: skip
    if not stats["losses/approx_kl"].item() <= PROBE_MAX_KL:
        return (f"minibatch_loss's log-probabilities of the rollouts' actions differ from the rollouts' own {at} "
                f"(the first ratio is not 1: approx_kl {stats['losses/approx_kl'].item():.3g})")  # fmt: skip
    per_row = np.full(rows, guidance)
    bounds = getattr(agent, "action_bounds", None)
    bounded = (lambda a: np.clip(as_array(a), *bounds)) if bounds is not None else as_array
    with torch.no_grad():
        mode = running("Agent.act", lambda: agent.act(raw_obs, per_row, deterministic=True))
        if not close(mode, bounded(defined.mode())):
            return f"Agent.act's deterministic actions differ from guided_policy's mode {at}"
        if not close(agent.act(raw_obs, per_row, noise=noise), bounded(expected)):
            return f"Agent.act's sampled actions differ from guided_policy's samples with the same noise {at}"
    return None


def probe_observations(observation_space, rows: int = PROBE_ROWS) -> np.ndarray:
    """A probe batch of observations from a fixed generator of its own (no global RNG is drawn): standard normal,
    within the space's bounds where it has them."""
    shape = (rows, *observation_space.shape)
    raw = np.random.default_rng(0).standard_normal(shape)
    low, high = getattr(observation_space, "low", None), getattr(observation_space, "high", None)
    if low is not None:
        raw = np.clip(raw, low, high)
    return raw


def observation_error(obs: np.ndarray, shape: tuple) -> str | None:
    """What `act` says of an observation (one, or a batch of them) that is not of the agent's `shape`, or None."""
    shape = tuple(shape)
    if obs.shape[-len(shape) :] != shape or obs.ndim not in (len(shape), len(shape) + 1):
        return f"the observation has shape {obs.shape}; the agent takes {shape}, or a batch of them (n, {', '.join(map(str, shape))})"
    return None


def acting_guidance(obs: np.ndarray, shape: tuple, guidance) -> np.ndarray:
    """`act`'s checks of its input, training's and the sweep's rule: a ValueError, one line, for an observation not
    of the agent's `shape` (one, or a batch), a guidance outside [0, 1000] or an observation holding a NaN or an
    infinity. Returns `guidance` as float64, a number or one per row."""
    if error := observation_error(obs, shape):
        raise ValueError(error)
    if guidance is None:
        raise ValueError("guidance must be a number in [0, 1000], got None")
    guidance = np.asarray(guidance, dtype=np.float64)
    if error := acting_error(obs, guidance):
        raise ValueError(error)
    return guidance


def guided_actions(
    agent, obs: np.ndarray, guidance, deterministic: bool, noise, null, draw_noise, seed=None
) -> np.ndarray:
    """`Agent.act` of both scripts, from its `acting_policy`: the actions of one observation or a batch (of the
    agent's `obs_shape`, checked by acting_guidance) at `guidance`, the mode if `deterministic`, else sampled with
    `noise` (checked by noise_error) or, where it is None, with the noise `draw_noise(distribution)` draws from
    torch's generator, or from one seeded by `seed` alone (an int or a numpy Generator; torch's own is left as it
    was); clipped to the agent's `action_bounds` (low, high) where it has them; `null` the unconditional branch
    where the caller holds it."""
    guidance = acting_guidance(obs, agent.obs_shape, guidance)
    if noise is not None and seed is not None:
        raise ValueError("pass noise or seed, not both: seed draws the noise")
    single = obs.ndim == 1
    pi = agent.acting_policy(obs[None] if single else obs, guidance, null)
    if deterministic:
        actions = pi.mode()
    elif noise is not None:
        noise = np.asarray(noise, dtype=np.float32)
        if error := noise_error(noise, held_draw(draw_noise, pi, None).shape, single):
            raise ValueError(error)
        actions = pi.sample(noise)
    else:
        actions = pi.sample(draw_noise(pi) if seed is None else held_draw(draw_noise, pi, seed))
    if (bounds := getattr(agent, "action_bounds", None)) is not None:
        low, high = bounds
        actions = np.maximum(np.minimum(actions, high), low)
    return actions[0] if single else actions


def held_draw(draw_noise, pi, seed) -> np.ndarray:
    """`draw_noise(pi)` with torch's generator seeded by `seed` (None: as it is), which is then put back as it was:
    `act`'s per-call seed, and the shape a given noise must have, at no cost to anyone's random stream."""
    if seed is not None and not (isinstance(seed, np.random.Generator) or (isinstance(seed, (int, np.integer))
                                                                            and 0 <= seed < 2**64)):  # fmt: skip
        raise ValueError(f"seed must be an integer in [0, 2**64) or a numpy Generator, got {seed!r}")
    state = torch.get_rng_state()
    try:
        if seed is not None:
            torch.default_generator.manual_seed(int(seed.integers(2**63)) if isinstance(seed, np.random.Generator)
                                                else int(seed))  # fmt: skip
        return np.asarray(draw_noise(pi))
    finally:
        torch.set_rng_state(state)


def noise_error(noise: np.ndarray, drawn: tuple, single: bool) -> str | None:
    """What `act` says of a `noise` that is not the shape of the noise it would draw itself (`drawn`: one row per
    observation; one observation also takes that row alone), or that holds a NaN or an infinity (a NaN action, an
    action at its bound, or an arbitrary argmax), or None."""
    wanted = [drawn[1:], drawn] if single else [drawn]
    if noise.shape not in wanted:
        rows = "one observation" if single else f"{drawn[0]} observations"
        return f"noise has shape {noise.shape}; for {rows} the agent's noise is {' or '.join(map(str, wanted))}"
    if not np.isfinite(noise).all():
        return "noise holds a NaN or an infinity"
    return None


@torch.no_grad()
def guidance_diagnostics(script, agent, obs: torch.Tensor, guidance: float) -> dict[str, float]:
    """How far guidance moves the policy of `script` (KL(pi_hat || pi_s), which the adaptive schedule holds near its
    target; `guidance` is this iteration's γ_train), and what the unconditional branch has learned; in eval mode,
    so no statistics move."""
    with eval_mode(agent):
        cond, null = agent.branches(obs)
        kl = script.guided_policy(cond, null, guidance).kl(cond).mean().item()
        stats = {"pgg/guidance": guidance, "pgg/kl_guided_vs_conditional": kl}
        if script.ACTION_SPACE == "continuous":
            stats["pgg/unconditional_mean_norm"] = agent.unconditional_mean().norm().item()
        else:
            stats["pgg/entropy_unconditional"] = null.entropy().sum().item()
    if isinstance(null_obs := getattr(agent, "null_obs", None), torch.Tensor):  # a fork may have a null head
        stats["pgg/null_embedding_norm"] = null_obs.norm().item()
    return stats


def trained_parameters(agent, guided: bool, probe_loss) -> list:
    """The parameters the optimizer trains. The null embedding trains wherever the objective reads it: guidance or
    dropout at some iteration (`guided`), or any other term of the loss (`probe_loss()`: the loss on an empty rollout
    with PPO's own actor pass, in eval mode so that a BatchNorm's statistics stay). Outside it, its all-zero gradient
    in the flat buffer would still change the clipping norm's rounding: without it the run is PPO's bits."""
    with eval_mode(agent):
        null_probe_loss = probe_loss()
    null_obs = dict(agent.named_parameters()).get("null_obs")  # none in a network without the null embedding
    trains_null = guided or reads_parameter(null_probe_loss, null_obs)
    return [p for name, p in agent.named_parameters() if trains_null or name != "null_obs"]
