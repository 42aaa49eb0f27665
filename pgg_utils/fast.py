"""Speed, not algorithm: what makes the scripts' small networks cheap on a CPU, with the same float
arithmetic (measured in benchmarks/README.md, equality tested in tests/test_equivalence.py)."""

from contextlib import nullcontext

import numpy as np
import torch
from torch import nn

from pgg_utils.policy import eval_mode, mode_dependent


def flatten_parameters(params: list[nn.Parameter]) -> nn.Parameter:
    """Moves `params` into one flat buffer and their gradients into another, and returns a Parameter
    over the two for the optimizer and gradient clipping, which on the CPU loop over their tensors in
    Python. The parameters become views of the buffers: the forward pass, autograd and the state dict
    are unchanged, and backward accumulates into the flat gradient (zero it in place, never set it to None)."""
    flat = nn.Parameter(torch.cat([p.detach().reshape(-1) for p in params]))
    flat.grad = torch.zeros_like(flat)
    offset = 0
    for p in params:
        p.data = flat.data[offset : offset + p.numel()].view_as(p)
        p.grad = flat.grad[offset : offset + p.numel()].view_as(p)
        offset += p.numel()
    return flat


# Layers the numpy forward computes itself, with the float32 operation torch does; any other layer sends
# that network through its own torch forward (correct, slower).
NUMPY_ACTIVATIONS = {nn.Tanh: np.tanh, nn.ReLU: lambda x: np.maximum(x, np.float32(0.0)), nn.Identity: lambda x: x}
PROBE_ROWS = 8


def numpy_network(module: nn.Module):
    """`module`'s forward for rollouts, as a function of a float32 numpy batch: numpy on views of its
    weights where it is an nn.Sequential of Linear layers and NUMPY_ACTIVATIONS, else the module's own
    torch forward. The numpy copy is checked against the module on a probe batch when built;
    ValueError with one line naming the network where they disagree (a layer treated wrongly)."""
    steps = numpy_steps(module)
    if steps is None:
        return torch_forward(module)

    def forward(x: np.ndarray) -> np.ndarray:
        for step in steps:
            x = step(x)
        return x

    in_features = next(layer.in_features for layer in module if type(layer) is nn.Linear)
    probe = np.random.default_rng(0).standard_normal((PROBE_ROWS, in_features)).astype(np.float32)
    expected = torch_forward(module)(probe)
    if not np.allclose(forward(probe), expected, rtol=1e-4, atol=1e-5):
        layers = ", ".join(type(m).__name__ for m in module.children())
        raise ValueError(f"the rollouts' numpy copy of the network ({layers}) disagrees with its torch module")
    return forward


def numpy_steps(module: nn.Module):
    """The numpy operations of an nn.Sequential of known layers (views of its weights), or None. Known
    means exactly these classes: a subclass may compute something else."""
    if not isinstance(module, nn.Sequential) or not any(type(layer) is nn.Linear for layer in module):
        return None
    steps = []
    for layer in module:
        if type(layer) is nn.Linear:
            weight = layer.weight.detach().numpy().T
            bias = None if layer.bias is None else layer.bias.detach().numpy()
            steps.append(lambda x, w=weight, b=bias: x @ w if b is None else x @ w + b)
        elif type(layer) in NUMPY_ACTIVATIONS:
            steps.append(NUMPY_ACTIVATIONS[type(layer)])
        else:
            return None
    return steps


def torch_forward(module: nn.Module):
    """`module`'s own forward on a float32 numpy batch, frozen where its training mode couples rows or draws noise
    (pgg_utils/policy.py): a rollout acts as a function of each observation alone, moving no statistics."""
    freeze = eval_mode if mode_dependent(module) else nullcontext

    def forward(x: np.ndarray) -> np.ndarray:
        with torch.no_grad(), freeze(module):
            return module(torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))).numpy()

    return forward


# --- evaluation ----------------------------------------------------------------------------------

# Evaluation forwards run on at least this many rows (padded). CPU BLAS rounds a 1-3 row product
# differently from a larger one, so a one-observation forward pads to it; on the AMD EPYC this was
# written on, products of 8 or more rows round alike.
MIN_FORWARD_ROWS = 8


def evaluation_forward(network: nn.Module, x: np.ndarray) -> np.ndarray:
    """`network(x)` for acting with a trained agent, float32, one row per row of `x`. The forward runs
    on at least MIN_FORWARD_ROWS rows (padded with copies of the first) in memory that torch allocated
    (64-byte aligned), so that the shapes and the alignment of every product are a function of the row
    count alone: a row's result depends on its own values, the row count and its position, never on
    the other rows' values."""
    rows = len(x)
    padded = torch.empty(max(rows, MIN_FORWARD_ROWS), x.shape[1])
    view = padded.numpy()
    view[:rows] = x
    view[rows:] = view[0]
    with torch.no_grad():
        return network(padded).numpy()[:rows]


def evaluation_network(network: nn.Module):
    """`network`'s forward for acting with a trained agent (evaluation_forward), as a function of a float32 numpy
    batch: the evaluation's counterpart of numpy_network."""
    return lambda x: evaluation_forward(network, x)


def branch_scale(logstd: torch.Tensor, acting: bool) -> tuple[np.ndarray, np.ndarray]:
    """(log σ, σ) of a Gaussian branch, (action_dim,): for a rollout, copies (its parameters, not live views) with
    numpy's exp; for `act`, views with torch's exp (their bits differ in the last place; each is what its runs and
    sweeps hold)."""
    logstd = logstd.detach()
    if acting:
        return logstd.numpy()[0], logstd.exp()[0].numpy()
    copy = logstd.numpy()[0].copy()
    return copy, np.exp(copy)


def standard_gumbel(uniform: np.ndarray) -> np.ndarray:
    """Standard Gumbel noise, in the dtype of `uniform` (samples in [0, 1); a 0 is raised to float32's
    smallest normal number, so the logarithms stay finite): argmax(logits + noise) is an exact
    categorical sample (the Gumbel-max trick), far cheaper than torch.distributions. Training's
    rollouts and the sweep draw their uniforms from their own generators and sample through this."""
    return -np.log(-np.log(np.maximum(uniform, np.finfo(np.float32).tiny)))
