"""The paper study: the paper's experiment written down (tasks, variants, γ lists, its numbers in data/),
the report against it, the statistics and figures of the tables, the held-out γ selection, and the
report generators of results/. It reads what training and the sweep write; training, the sweep and
pgg_utils import nothing of it (tests/test_extending.py). Its entry points are plot_results.py and
reproduce.py at the top level and the scripts in this folder."""
