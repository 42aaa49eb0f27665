"""A checkpoint's contract with its task (pgg_utils/tasks.py): every change of a space is named in one line."""

import numpy as np
from gymnasium import spaces as gs

from pgg_utils import tasks


def test_the_same_spaces_match_and_each_change_is_named():
    box = gs.Box(-1.0, 1.0, (3,), np.float32)
    contract = tasks.describe(gs.Box(-np.inf, np.inf, (11,)), box)
    assert tasks.mismatch(contract, gs.Box(-np.inf, np.inf, (11,)), box) is None
    assert "observation shape (11,) in training, (1,) now" in tasks.mismatch(contract, gs.Box(-1, 1, (1,)), box)
    assert "action shape" in tasks.mismatch(contract, gs.Box(-np.inf, np.inf, (11,)), gs.Box(-1.0, 1.0, (2,)))
    assert "action high" in tasks.mismatch(contract, gs.Box(-np.inf, np.inf, (11,)), gs.Box(-1.0, 2.0, (3,)))
    assert "Box in training, Discrete now" in tasks.mismatch(contract, gs.Box(-np.inf, np.inf, (11,)), gs.Discrete(3))


def test_discrete_n_and_start_are_part_of_the_contract():
    obs = gs.Box(-1, 1, (4,))
    contract = tasks.describe(obs, gs.Discrete(3, start=-1))
    assert contract["action"] == {"type": "Discrete", "n": 3, "start": -1}
    assert "action n 3 in training, 4 now" in tasks.mismatch(contract, obs, gs.Discrete(4, start=-1))
    assert "action start -1 in training, 0 now" in tasks.mismatch(contract, obs, gs.Discrete(3))


def test_an_older_checkpoint_is_held_to_the_sizes_it_records():
    old_discrete = tasks.recorded({"obs_dim": 3, "n_actions": 1})
    assert tasks.mismatch(old_discrete, gs.Box(-1, 1, (3,)), gs.Discrete(1)) is None
    assert "observation shape (3,) in training, (1,) now" in tasks.mismatch(
        old_discrete, gs.Box(-1, 1, (1,)), gs.Discrete(1)
    )
    assert "action n 1 in training, 4 now" in tasks.mismatch(old_discrete, gs.Box(-1, 1, (3,)), gs.Discrete(4))
    old_box = tasks.recorded({"obs_dim": 11, "action_dim": 3})
    assert tasks.mismatch(old_box, gs.Box(-1, 1, (11,)), gs.Box(-5.0, 5.0, (3,))) is None  # old bounds not held
