import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
torch.set_num_threads(1)


@pytest.fixture
def compiled_calls(monkeypatch) -> list:
    """torch.compile still compiles, and each call of what it compiled is recorded in this list."""
    calls, real_compile = [], torch.compile

    def spy_compile(fn):
        compiled = real_compile(fn)

        def counted(*args, **kwargs):
            calls.append(fn)
            return compiled(*args, **kwargs)

        return counted

    monkeypatch.setattr(torch, "compile", spy_compile)
    return calls
