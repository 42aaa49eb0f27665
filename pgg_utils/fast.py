"""Speed, not algorithm: what makes the scripts' small networks cheap on a CPU, with the same float
arithmetic (measured in benchmarks/README.md, equality tested in tests/test_equivalence.py)."""

import numpy as np
import torch
from torch import nn


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


def numpy_layers(mlp: nn.Sequential) -> list[tuple[np.ndarray, np.ndarray]]:
    """(weight transposed, bias) of each Linear layer, as numpy views of the parameters."""
    return [
        (layer.weight.detach().numpy().T, layer.bias.detach().numpy()) for layer in mlp if isinstance(layer, nn.Linear)
    ]


def numpy_forward(layers, x: np.ndarray) -> np.ndarray:
    """The agents' Linear-Tanh-...-Linear networks, in numpy."""
    for weight, bias in layers[:-1]:
        x = np.tanh(x @ weight + bias)
    weight, bias = layers[-1]
    return x @ weight + bias
