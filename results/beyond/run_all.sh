#!/usr/bin/env bash
# The runs of "Beyond the paper" (results/beyond/README.md), one set after another with the project's
# launcher: each trains its grid (5 seeds x 1M steps, checkpoints every 200k), sweeps the paper's
# continuous gamma list with 50 episodes per cell and writes its tables, figures and agents to
# results/beyond/<task>. Rerunning it skips finished runs and cells and resumes the others. Sets whose
# baselines are the continuous table's runs train eager, as those did (the same code class); Reacher-v4,
# whose baselines are trained here too, trains with --compile (~1.25x faster).
set -uo pipefail
cd "$(dirname "$0")/../.."
beyond() {  # task, variants...
    local env=$1; shift
    python reproduce.py --preset continuous --envs "$env" --variants "$@" --root runs/beyond \
        --results "results/beyond/$env" --workers "${WORKERS:-2}" ${COMPILE:-}
    echo "set $env done: exit $? at $(date -u +%FT%TZ)"
}
beyond Hopper-v4 pgg_g1to1.2 pgg_adaptive1.1_kl0.04
COMPILE=--compile beyond Reacher-v4 ppo pgg_g1.1 pgg_g1.1_goal
beyond Walker2d-v4 pgg_g1to1.2 pgg_adaptive1.1_kl0.04
beyond Pusher-v4 pgg_g1.1_goal
beyond Humanoid-v4 pgg_g1to1.2 pgg_adaptive1.1_kl0.04
