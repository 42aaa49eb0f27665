"""What the scripts share besides the algorithm, as CleanRL keeps it in `cleanrl_utils`: the run
arguments, run directories and checkpoints, files, progress, child processes, the paper's tasks and
variants, the statistics, the reports and the figures, videos. It imports none of the scripts: they import it."""
