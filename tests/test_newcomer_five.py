"""What a newcomer broke, round five, and what a user of the ecosystem's tools hit (issue 59): unchecked noise, a
seed lost from a whole configuration, a manifest that could delete a user's file, aggregates left out without a
word on a user's own tasks; the loud cases, each one line naming its real cause; and the field's habits
(Stable-Baselines3's `predict`, a per-call seed)."""

import numpy as np
import pytest
import torch
from conftest import SCRIPTS
from test_plots import SEED_MEANS, episode_rows, write_episodes

import plot_results as plots

# --- silent: act's noise --------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_act_refuses_noise_that_is_not_finite_in_one_line_naming_it(kind):
    """NaN noise returned NaN actions, an infinite one the bound, and on a discrete agent `[nan, nan, nan]` the
    argmax's first action whatever the observation: noise is checked as the observation is."""
    agent = SCRIPTS[kind].Agent(4, 3)
    for bad in (np.full(3, np.nan), np.full(3, np.inf), np.array([[0.0, -np.inf, 0.0]])):
        with pytest.raises(ValueError, match=r"^noise holds a NaN or an infinity$"):
            agent.act(np.zeros(4), 1.5, noise=bad)


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_act_names_noise_of_the_wrong_shape_and_the_shape_it_needs(kind):
    """numpy's "operands could not be broadcast together with shapes (3,) (5,)" named no argument, and a noise that
    broadcast (one number for every action, a batch's noise for one observation) acted silently."""
    agent = SCRIPTS[kind].Agent(4, 3)
    one = "the agent's noise is (3,) or (1, 3)"
    for noise, shape, wanted in ((np.zeros(5), "(5,)", one), (np.zeros(1), "(1,)", one), (np.zeros(()), "()", one),
                                 (np.zeros((2, 3)), "(2, 3)", one)):  # fmt: skip
        with pytest.raises(ValueError) as refused:
            agent.act(np.zeros(4), 1.0, noise=noise)
        assert str(refused.value) == f"noise has shape {shape}; for one observation {wanted}"
    with pytest.raises(ValueError) as refused:
        agent.act(np.zeros((5, 4)), 1.0, noise=np.zeros(3))
    assert str(refused.value) == "noise has shape (3,); for 5 observations the agent's noise is (5, 3)"
    state = torch.get_rng_state()
    assert agent.act(np.zeros(4), 1.0, noise=np.zeros(3)).shape == agent.act(np.zeros(4), 1.0, noise=np.zeros((1, 3))).shape
    assert torch.equal(torch.get_rng_state(), state)  # checking the shape draws nothing from torch's generator


# --- silent: a configuration short of seeds in every cell -----------------------------------------


def test_a_configuration_short_of_a_seed_in_every_cell_is_marked_against_the_others(tmp_path, capsys):
    """With no written.csv and one variant's seed 2 gone from every cell, the tables showed that variant's 2-seed
    cells bare under "mean ± 95% CI over seeds" beside the others' 3, and no note: only a cell short within its own
    configuration was marked."""
    rows = [r for r in episode_rows(SEED_MEANS) if r["run"] != "CartPole-v1__pgg_g1.1__s2"]
    write_episodes(tmp_path / "sweep" / "episodes.csv", rows)
    plots.generate(plots.Args(sweeps=(str(tmp_path / "sweep"),), output=str(tmp_path / "out")))
    err = capsys.readouterr().err
    assert ("note: 1 configuration(s) hold fewer seeds in every cell than the other configurations of their task, "
            "and say so in the tables: CartPole-v1 pgg_g1.1 (2 of 3 seeds)") in err  # fmt: skip
    assert "cell(s) hold fewer seeds than the other cells of their configuration" not in err
    table = (tmp_path / "out" / "table_discrete.md").read_text()
    assert table.count("(2 of 3 seeds)") == 4  # CartPole's four PGG cells, at two steps and two γ
    assert "467.0 ± 12.7 (2 of 3 seeds)" in table
    assert "(2 of 3 seeds)" in (tmp_path / "out" / "table_discrete.tex").read_text()
