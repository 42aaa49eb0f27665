"""What acts is what trains, checked on the agent as it trains (issue 56): forks as a researcher writes them in their
first week, each a copied script that edits one path and not the others. Each trained silently before these checks
(the start-up probe ran on a fresh agent, where log-stds and the null embedding are 0 and the paths coincide) and
now stops in one line naming the path, or, where the project owns the path (the normaliser), acts as it trains."""

import subprocess
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from conftest import ROOT, one_line_error, run_main

from pgg_utils import runs, scripts
from pgg_utils.policy import randomised

PENDULUM = ["--env-id", "Pendulum-v1", "--total-timesteps", "1024", "--checkpoint-interval", "512", "--num-steps",
            "256", "--num-minibatches", "4", "--update-epochs", "2", "--torch-threads", "1"]  # fmt: skip


def fork(tmp_path: Path, *edits: tuple[str, str]) -> Path:
    """A copy of the continuous script with each (anchor, replacement) made once."""
    source = (ROOT / "ppo_pgg_continuous.py").read_text()
    for anchor, replacement in edits:
        assert source.count(anchor) == 1, anchor
        source = source.replace(anchor, replacement)
    path = tmp_path / "ppo_pgg_fork.py"
    path.write_text(source)
    return path


def train_fork(path: Path, tmp_path: Path, *flags: str) -> subprocess.CompletedProcess:
    """`python <fork> *flags`, the fork imported (scripts.load_module, as the sweep imports a fork) and its main run
    in this process (conftest.run_main: no Python and torch start-up per fork)."""
    return run_main(scripts.load_module(path), *PENDULUM, "--output-dir", str(tmp_path / "runs"), *flags)


# The null branch with a learned σ of its own, mixed by natural parameters in guided_policy, but null_logstd (which
# the rollouts and `act` read) left as it was: equal at initialisation (both 0), apart as soon as either moves.
OWN_NULL_SIGMA = (
    ("        self.actor_logstd = nn.Parameter(torch.zeros(1, action_dim))\n",
     ("        self.actor_logstd = nn.Parameter(torch.zeros(1, action_dim))\n"
     "        self.null_own_logstd = nn.Parameter(torch.zeros(1, action_dim))\n")),
    ("Gaussian(mean_null, self.null_logstd())  # PGG\n", "Gaussian(mean_null, self.null_own_logstd)  # PGG\n"),
    ("    return Gaussian(guide(cond.mean, null.mean, guidance), cond.logstd, cond.std)  # PGG\n",
     ("    precision = (1 - guidance) / null.std**2 + guidance / cond.std**2\n"
     "    mean = ((1 - guidance) * null.mean / null.std**2 + guidance * cond.mean / cond.std**2) / precision\n"
     "    return Gaussian(mean, -0.5 * precision.log())\n")),
)  # fmt: skip


def test_a_null_branch_with_its_own_sigma_that_the_fast_path_ignores_stops_before_training(tmp_path):
    """The probe runs on a copy of the agent with every parameter drawn at random: the null's own σ and the policy's
    differ there, so the rollouts (which read null_logstd) disagree with the definition, one line, exit 2."""
    done = train_fork(fork(tmp_path, *OWN_NULL_SIGMA), tmp_path, "--guidance", "2")
    assert "FastPolicy.act" in one_line_error(done, 2)


def test_the_probe_copy_draws_every_parameter_and_buffer_and_moves_no_global_rng():
    module = scripts.original("continuous")
    agent = module.Agent(5, 2)
    state = torch.get_rng_state()
    probed = randomised(agent)
    assert torch.equal(state, torch.get_rng_state())
    fresh, drawn = dict(agent.state_dict()), probed.state_dict()
    for name, value in drawn.items():
        if value.is_floating_point():
            assert not torch.equal(value, fresh[name]), name
    assert torch.equal(drawn["null_mask"] if "null_mask" in drawn else torch.ones(1), torch.ones(1))
    assert (probed.obs_norm.var > 0).all() and probed.obs_norm.count > 0


# A normaliser the fork swaps in (here: none at all). The rollouts, `act` and the sweep normalise through the agent's
# own object, so the fork trains on what it is swept on.
NO_NORMALISATION = (
    ("ACTION_SPACE = \"continuous\"",
     ("class Unnormalised(RunningObsNorm):\n"
     "    def normalise(self, raw_obs):\n"
     "        return np.asarray(raw_obs, dtype=np.float32)\n\n\nACTION_SPACE = \"continuous\"")),
    ("        self.obs_norm = RunningObsNorm(obs_dim, obs_clip)\n",
     ("        self.obs_norm = Unnormalised(obs_dim, obs_clip)\n")),
)  # fmt: skip


def test_a_normaliser_the_fork_changes_is_the_one_the_rollouts_use(tmp_path, monkeypatch):
    """Before, the rollouts normalised through a copy of the formula (ObservationStatistics) and `act` through the
    agent's object: a fork without normalisation trained on normalised input and was swept on raw input."""
    module = scripts.load_module(fork(tmp_path, *NO_NORMALISATION))
    rollouts = []
    real_update = module.ppo_update

    def spy(agent, optimizer, buf, *rest, **kwargs):
        rollouts.append({"obs": buf.obs.clone(), "actions": buf.actions.clone()})
        return real_update(agent, optimizer, buf, *rest, **kwargs)

    monkeypatch.setattr(module, "ppo_update", spy)
    args = module.Args(env_id="Pendulum-v1", total_timesteps=512, checkpoint_interval=512, num_steps=256,
                       num_minibatches=4, update_epochs=2, output_dir=str(tmp_path / "runs"), guidance=1.3)  # fmt: skip
    runs.train_in_process(module, args)
    # the raw observations of the first rollout, replayed from its actions
    env, replayed = gym.make("Pendulum-v1"), []
    obs, _ = env.reset(seed=args.seed)
    for action in rollouts[0]["actions"][:, 0].numpy():
        replayed.append(obs)
        obs, _, terminated, truncated, _ = env.step(np.clip(action, -2.0, 2.0))
        if terminated or truncated:
            obs, _ = env.reset()
    np.testing.assert_array_equal(rollouts[0]["obs"][:, 0].numpy(), np.asarray(replayed, dtype=np.float32))


# The unconditional mean memoised the first time the rollouts ask for it (a "speed-up"): right on the probe's copy,
# stale on the live agent once the first update moves the null embedding.
MEMOISED_NULL = (
    ("        return null_pass(self.actor_mean, self.null_obs.unsqueeze(0))[0]  # PGG\n",
     ("        if getattr(self, \"memo\", None) is None:\n"
     "            self.memo = null_pass(self.actor_mean, self.null_obs.unsqueeze(0))[0].detach()\n"
     "        return self.memo\n")),
)  # fmt: skip


def test_a_path_that_goes_stale_as_the_agent_trains_stops_at_the_next_update(tmp_path):
    """The first minibatch of every update, before any step, must give the rollout's actions the rollout's
    log-probabilities; a stale rollout path breaks that from the second update on: one line, the checkpoints written
    before it kept, exit 1."""
    done = train_fork(fork(tmp_path, *MEMOISED_NULL), tmp_path, "--guidance", "2", "--learning-rate", "0.01")
    line = one_line_error(done, 1)
    assert "the first minibatch's ratio is not 1" in line and "FastPolicy.act" in line


# `act` alone memoises its fast path (the sweep's path, which training never calls): right on the probe's copy and at
# the first checkpoint, stale at the next.
MEMOISED_ACTING_NULL = (
    ("        fast = FastPolicy(self, acting=True, mean_null=mean_null)  # PGG\n",
     ("        if getattr(self, \"acting_memo\", None) is None:\n"
      "            self.acting_memo = FastPolicy(self, acting=True, mean_null=mean_null)\n"
      "        fast = self.acting_memo\n")),
)  # fmt: skip


def test_act_that_goes_stale_as_the_agent_trains_stops_at_the_next_checkpoint(tmp_path):
    """At every checkpoint, `act` on the probe batch must equal the definition on the trained weights; the
    checkpoint that would carry a stale `act` is not written, the earlier ones are kept."""
    done = train_fork(fork(tmp_path, *MEMOISED_ACTING_NULL), tmp_path, "--guidance", "2")
    line = one_line_error(done, 1)
    assert line.startswith("error: at step 1,024: Agent.act") and "checkpoints up to step_000000512.pt are kept" in line
    assert [p.name for p in (tmp_path / "runs").glob("*/checkpoints/*.pt")] == ["step_000000512.pt"]


# A distribution the fork builds in Agent.branches and reads in guided_policy (here a σ floor the branches carry), with
# the fast path left as it was: the rollouts' Gaussians lack it. Before, a traceback through the probe.
FLOORED = (
    ("class Agent(nn.Module):",
     ("class Floored(Gaussian):\n"
      "    floor = 0.1\n\n\n"
      "class Agent(nn.Module):")),
    ("        return Gaussian(mean_cond, self.actor_logstd), Gaussian(mean_null, self.null_logstd())  # PGG\n",
     "        return Floored(mean_cond, self.actor_logstd), Floored(mean_null, self.null_logstd())  # PGG\n"),
    ("    return Gaussian(guide(cond.mean, null.mean, guidance), cond.logstd, cond.std)  # PGG\n",
     "    return Gaussian(guide(cond.mean, null.mean, guidance), cond.logstd, cond.std + cond.floor)  # PGG\n"),
)  # fmt: skip


def test_a_path_that_cannot_run_on_the_probe_batch_is_named_in_one_line(tmp_path):
    """A fork whose distribution the fast path does not build raised AttributeError through the probe (a traceback);
    now the path that raised is named with the error's first line, exit 2, before training."""
    done = train_fork(fork(tmp_path, *FLOORED), tmp_path, "--guidance", "2")
    line = one_line_error(done, 2)
    assert "the rollouts (FastPolicy.act) raised AttributeError on a probe batch" in line and "floor" in line


def test_observations_the_networks_cannot_take_are_refused_in_one_line(tmp_path):
    """A frame stack without a flatten in make_env gives (4, 3) observations: a traceback from the normaliser in the
    start-up probe before; now one line naming the shape and the flatten, exit 2."""
    stacked = (
        (
            "        return env\n\n    return thunk\n",
            "        return gym.wrappers.FrameStackObservation(env, 4)\n\n    return thunk\n",
        ),
    )
    done = train_fork(fork(tmp_path, *stacked), tmp_path)
    line = one_line_error(done, 2)
    assert "observations have shape (4, 3)" in line and "FlattenObservation" in line
