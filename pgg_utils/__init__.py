"""What the scripts share besides the algorithm, as CleanRL keeps it in `cleanrl_utils`: the run
arguments and their rules, run directories and checkpoints, a run's identity and configuration, which
script a checkpoint names, files, progress, child processes, the sweep's cells and its pooling over
seeds, videos, and a behaviour-cloned null for trained agents. It imports none of the scripts (it
finds a checkpoint's by path, as bc_null finds the sweep's episode loop) and nothing of the paper study
(paper_study/)."""
