"""The engine: what the training scripts and the sweep share besides the algorithm, as CleanRL keeps it in
`cleanrl_utils`: runs and checkpoints, the task as make_env makes it, the distributions and the fast path, the one
evaluation loop and the sweep's cells, and the reading of results (docs/layout.md lists the modules by concern). It
imports none of the scripts (it finds a checkpoint's by path) and nothing of the study (paper_study/, beyond/):
tests/test_layers.py."""
