"""The paper study: the paper's experiment written down (tasks, variants, γ lists, its numbers in data/), the
report against it, the statistics and figures of the tables and the held-out γ selection, for plot_results.py and
reproduce.py. It reads what training and the sweep write; they and pgg_utils import nothing of it, and it imports
nothing of beyond/ (tests/test_layers.py, docs/layout.md). Its tools run as `python -m paper_study.<tool>`."""
