"""What the scripts share besides the algorithm, as CleanRL keeps it in `cleanrl_utils`: files, run
directories and checkpoints, progress, the paper's tasks and variants, and the statistics. It imports
none of the scripts: they import it."""
