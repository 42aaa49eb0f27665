#!/usr/bin/env bash
# The runs of "Beyond the paper" (results/beyond/README.md), one set after another with the project's
# launcher: each trains its grid (5 seeds x 1M steps, checkpoints every 200k), sweeps the paper's
# continuous gamma list with 50 episodes per cell and writes its tables, figures and agents to
# results/beyond/<task>. Rerunning it skips finished runs and cells and resumes the others. Every set
# trains with --compile, as the continuous table's runs (the baselines) did.
set -uo pipefail
cd "$(dirname "$0")/../.."
beyond() {  # task, variants...: train and sweep, then the held-out gamma on a fresh sweep, then the report
    local env=$1; shift
    python reproduce.py --preset continuous --envs "$env" --variants "$@" --root runs/beyond \
        --results "results/beyond/$env" --workers "${WORKERS:-2}" --compile &&
    cp runs/beyond/sweep/evaluated_by.csv "results/beyond/$env/evaluated_by.csv"  # which file evaluated each agent
    echo "set $env trained and swept: exit $? at $(date -u +%FT%TZ)"
    python eval_gamma_sweep.py "results/beyond/$env/agents" --eval-seed 20000 --workers "${WORKERS:-2}" \
        --output "runs/sweeps/beyond_fresh_$env" &&
    cp "runs/sweeps/beyond_fresh_$env/evaluated_by.csv" "results/beyond/$env/heldout_evaluated_by.csv" &&
    python -m paper_study.heldout_gamma "results/beyond/$env/episodes.csv" \
        "runs/sweeps/beyond_fresh_$env/episodes.csv" --output "results/beyond/$env"
    echo "set $env held-out gamma: exit $? at $(date -u +%FT%TZ)"
}
goal_distance() {
    python -m beyond.goal_distance results/beyond/Reacher-v4/agents results/beyond/Pusher-v4/agents \
        results/continuous/agents --steps 1000000 --output results/beyond/goal_distance.csv
}
report() {
    python -m beyond.report results/beyond --table results/continuous/episodes.csv --runs runs/beyond
}
beyond Hopper-v4 pgg_g1to1.2 pgg_adaptive1.1_kl0.04 && report
beyond Pusher-v4 pgg_g1.1_goal && goal_distance && report
beyond Reacher-v4 ppo pgg_g1.1 pgg_g1.1_goal && goal_distance && report
beyond Walker2d-v4 pgg_g1to1.2 pgg_adaptive1.1_kl0.04 && report
beyond Humanoid-v4 pgg_g1to1.2 pgg_adaptive1.1_kl0.04 && report
