"""The behaviour-cloned null (pgg_utils/bc_null.py): the fit reaches the maximum-likelihood unconditional
branch with the actor frozen, and the fitted checkpoint is swept as what it is, never pooled with its source."""

import dataclasses

import numpy as np
import pytest
import torch
from conftest import ROOT, small_args, train

import eval_gamma_sweep as sweep
import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import bc_null, checkpoints, files, identity, scripts


def test_the_fit_moves_only_the_null_embedding_to_the_actions_maximum_likelihood():
    torch.manual_seed(0)
    agent = ppo_pgg_continuous.Agent(5, 2)
    with torch.no_grad():
        agent.actor_mean[-1].weight.mul_(100.0)  # a trained actor's reach; a fresh one's outputs are ~0.01
    before = {name: value.clone() for name, value in agent.state_dict().items()}
    actions = np.random.default_rng(0).normal(loc=[0.3, -0.2], scale=0.5, size=(400, 2))
    null, nll = bc_null.fit_null(agent, "continuous", actions, 2000, 0.05)
    with torch.no_grad():
        mean = agent.actor_mean(null[None])[0].numpy()
    np.testing.assert_allclose(mean, actions.mean(0), atol=1e-3)  # a Gaussian's maximum: the mean action
    sigma = agent.actor_logstd.exp()[0].detach().numpy()
    expected = (0.5 * ((actions - mean) / sigma) ** 2 + np.log(sigma) + 0.5 * np.log(2 * np.pi)).sum(-1).mean()
    assert nll == pytest.approx(expected, rel=1e-4)
    assert all(torch.equal(before[name], value) for name, value in agent.state_dict().items())  # the agent untouched

    discrete = ppo_pgg_discrete.Agent(4, 3)
    with torch.no_grad():
        discrete.actor[-1].weight.mul_(100.0)
    actions = np.array([0] * 60 + [1] * 30 + [2] * 10)
    null, nll = bc_null.fit_null(discrete, "discrete", actions, 2000, 0.05)
    with torch.no_grad():
        np.testing.assert_allclose(torch.softmax(discrete.actor(null[None])[0], -1).numpy(), [0.6, 0.3, 0.1], atol=2e-3)


@pytest.mark.slow
def test_a_fitted_null_is_swept_as_its_own_configuration_beside_its_source(tmp_path):
    run_dir = train(ppo_pgg_discrete, small_args("discrete", tmp_path / "runs", guidance=1.1, cond_dropout=0.0))
    source = checkpoints.checkpoint_path(run_dir, 1536)
    args = bc_null.Args(paths=(str(source),), output=str(tmp_path / "runs" / "bc"), episodes=3)
    fitted = bc_null.fitted_checkpoint(source, checkpoints.read_checkpoint_file(source), args, (), "fitted__bcnull")
    assert fitted["null_fit"]["method"] == "behaviour cloning" and fitted["null_fit"]["episodes"] == 3
    fitter = fitted["null_fit"]["code"]  # the code that fitted it, beside the training's own `code`
    assert fitter["files"][0] == "bc_null.py" and fitter["script_sha1"] == scripts.file_sha1(
        ROOT / "pgg_utils" / "bc_null.py"
    )
    assert fitted["null_fit"]["machine"] and fitted["null_fit"]["versions"]["torch"] == torch.__version__
    assert not torch.equal(fitted["model"]["null_obs"], checkpoints.read_checkpoint_file(source)["model"]["null_obs"])
    assert identity.config_label(fitted).endswith("null=bc num_steps=64 total_timesteps=1536")
    destination = tmp_path / "runs" / "bc" / "fitted__bcnull" / "checkpoints" / source.name
    destination.parent.mkdir(parents=True)
    destination.write_bytes(checkpoints.checkpoint_bytes(fitted))
    with pytest.raises(ValueError, match="already holds a fitted null branch"):
        bc_null.fitted_checkpoint(destination, checkpoints.read_checkpoint_file(destination), args, (), "x")
    sweep.sweep(sweep.Args(paths=(str(tmp_path / "runs"),), output=str(tmp_path / "sweep"), gammas=(1.0, 2.0),
                           episodes=2, steps=(1536,)))  # fmt: skip
    summary = files.read_csv(tmp_path / "sweep" / "summary.csv")
    assert sorted((row["null_branch"], row["n_seeds"]) for row in summary) == [("bc", "1")] * 2 + [("learned", "1")] * 2


def test_a_partial_null_is_refused(tmp_path):
    args = dataclasses.replace(small_args("continuous", tmp_path / "runs"), env_id="Reacher-v4", null_dims=(4, 5))
    run_dir = train(ppo_pgg_continuous, args)
    with pytest.raises(ValueError, match="replaces some observation dimensions only"):
        path = checkpoints.checkpoint_path(run_dir, 768)
        bc_null.fitted_checkpoint(path, checkpoints.read_checkpoint_file(path), bc_null.Args(paths=()), (), "x")
