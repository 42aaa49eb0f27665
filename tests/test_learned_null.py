"""What the learned null is (beyond/learned_null.py): the command, or Reacher's goal, whose conditional policy
is closest to the agent's unconditional one on its own states."""

import csv
from dataclasses import replace

import numpy as np
import pytest
import torch
from conftest import SCRIPTS, one_line_error, run_main, run_script, small_args, train

from beyond import learned_null
from paper_study.cheetah_velocity import COMMAND_INDEX, ENV_ID
from pgg_utils import checkpoints, scripts
from pgg_utils.distributions import Gaussian


@pytest.fixture(scope="module")
def command_run(tmp_path_factory):
    """A tiny PGG run of the command task with the null on the command, trained in this process."""
    tmp_path = tmp_path_factory.mktemp("command")
    args = small_args("continuous", tmp_path, env_id=ENV_ID, null_dims=(COMMAND_INDEX,), cond_dropout=0.0)
    return train(SCRIPTS["continuous"], replace(args, total_timesteps=256, checkpoint_interval=256))


def loaded(run):
    agent, ckpt = scripts.load_checkpoint(checkpoints.checkpoints_of(run)[-1])
    return agent, scripts.training_module(ckpt)[0].make_env(ckpt["env_id"])


@pytest.mark.slow
def test_a_command_null_is_found_at_the_command_its_embedding_stands_for(command_run):
    """A null on the command replaces the command's normalised value by the embedding's: π(a|s, ∅) is then exactly
    π(a|s, c) at the raw command c that normalises to it. Set to stand for 1.23 m/s, the tool finds 1.23 with a KL of
    0 there and every state's own closest command on it; the untrained embedding (0: the running mean) is found at
    the mean command."""
    agent, make_env = loaded(command_run)
    # The commands of [0, 2]'s running statistics: a tiny run saw one command, too few to normalise by.
    agent.obs_norm.mean[COMMAND_INDEX], agent.obs_norm.var[COMMAND_INDEX] = 1.0, 1 / 3
    states = learned_null.own_states(agent, make_env, 1, 40_000)
    first, _ = make_env().reset(seed=40_000)
    assert len(states) == 1000 and np.array_equal(states[0], first)  # one episode's every observation, in order
    condition = learned_null.CONDITIONS[ENV_ID]
    untrained = learned_null.nearest_condition(agent, states, condition)
    assert untrained["pseudo_command"] == 1.0 and untrained["kl_at_pseudo"] == pytest.approx(0.0, abs=1e-9)
    stands_for = agent.obs_norm.normalise(learned_null.set_command(states[:1], np.array([1.23])))[0, COMMAND_INDEX]
    with torch.no_grad():
        agent.null_obs[COMMAND_INDEX] = float(stands_for)
    found = learned_null.nearest_condition(agent, states, condition)
    assert found["pseudo_command"] == 1.23 and found["kl_at_pseudo"] == pytest.approx(0.0, abs=1e-9)
    assert found["per_state_spread"] == 0.0 and found["at_grid_edge"] == "no" and found["kl_at_own"] > 0


class GoalAgent:
    """A stand-in for a Reacher agent: its mean action is a smooth function of the target and the fingertip, and its
    null branch is its conditional policy at the goal (0.05, −0.1)."""

    def mean(self, obs):
        fingertip, target = obs[:, 8:10] + obs[:, 4:6], obs[:, 4:6]
        return np.tanh(3 * target + fingertip * fingertip.sum(-1, keepdims=True))

    def acting_policy(self, obs, guidance):
        null = self.mean(learned_null.set_goal(obs, np.array([0.05, -0.1])))
        return Gaussian(guidance * self.mean(obs) + (1 - guidance) * null, np.full(2, -1.0))


def test_a_goal_is_moved_with_the_fingertip_held_and_a_goal_null_is_found_at_its_goal():
    """Reacher's goal dims 4, 5 take the candidate and fingertip − target (8, 9) moves with it, the fingertip and the
    other dims unchanged; a null that is the policy at one goal is found there on the 0.01 m lattice."""
    obs = np.random.default_rng(0).uniform(-0.2, 0.2, size=(300, 11))
    moved = learned_null.set_goal(obs, np.array([0.1, -0.05]))
    assert np.allclose(moved[:, 8:10] + moved[:, 4:6], obs[:, 8:10] + obs[:, 4:6]) and np.all(
        moved[:, 4:6] == [0.1, -0.05]
    )
    assert np.array_equal(np.delete(moved, [4, 5, 8, 9], axis=1), np.delete(obs, [4, 5, 8, 9], axis=1))
    found = learned_null.nearest_condition(GoalAgent(), obs, learned_null.CONDITIONS["Reacher-v4"])
    assert (found["pseudo_goal_x"], found["pseudo_goal_y"]) == (0.05, -0.1)
    assert found["kl_at_pseudo"] == pytest.approx(0.0, abs=1e-12) and found["per_state_spread"] == 0.0


def test_the_kl_is_that_of_two_diagonal_gaussians():
    """KL(p ‖ q) per row, against torch's for Normals of different σ."""
    p = Gaussian(np.array([[0.1, -0.3]]), np.array([-0.5, 0.2]))
    q = Gaussian(np.array([[0.4, 0.1]]), np.array([0.1, -0.4]))
    expected = torch.distributions.kl_divergence(torch.distributions.Normal(torch.tensor(p.mean), torch.tensor(p.std)),
                                                 torch.distributions.Normal(torch.tensor(q.mean), torch.tensor(q.std)))  # fmt: skip
    assert learned_null.gaussian_kl(p, q) == pytest.approx(expected.sum(-1).numpy())


@pytest.mark.slow
def test_the_cli_writes_a_row_per_checkpoint_and_refuses_bad_input_in_one_line(command_run, tmp_path):
    """A row per checkpoint with the CSV's columns; another task's checkpoint is named and left out, and with nothing
    left, or a zero episode count, one line of error and exit 2, no file."""
    tool = "beyond/learned_null.py"
    proc = run_script(tool, str(command_run), "--episodes", "1", "--output", str(tmp_path / "n.csv"))
    assert proc.returncode == 0, proc.stderr
    with open(tmp_path / "n.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    assert reader.fieldnames == learned_null.COLUMNS and len(rows) == 1
    assert rows[0]["variant"] == "pgg_g1.1_null17" and rows[0]["null_dims"] == "17" and rows[0]["states"] == "1000"
    assert -1 <= float(rows[0]["pseudo_command"]) <= 4 and rows[0]["pseudo_goal_x"] == ""
    other = train(
        SCRIPTS["continuous"], small_args("continuous", tmp_path, total_timesteps=256, checkpoint_interval=256)
    )
    proc = run_main(learned_null, str(other), "--output", str(tmp_path / "x.csv"))  # the errors: main in this process
    assert (
        proc.returncode == 2 and "Traceback" not in proc.stderr and "Humanoid-v4 has no condition here" in proc.stderr
    )
    assert proc.stderr.strip().splitlines()[-1].startswith("error: no checkpoint of")
    assert not (tmp_path / "x.csv").exists()
    assert "--episodes must be positive" in one_line_error(
        run_main(learned_null, str(other), "--episodes", "0", "--output", "y.csv")
    )
