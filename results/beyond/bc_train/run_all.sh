#!/usr/bin/env bash
# The set of the variant that clones the rollout's actions while it trains (pgg_g1.1_bc0.1: γ_train 1.1,
# --null-bc-coef 0.1, route null; results/beyond/README.md), one task after another with the launcher:
# 5 seeds x 1M steps with --compile, checkpoints every 200k, swept at the paper's continuous γ (episode
# seeds 10000+), then on fresh episodes (20000+, committed as heldout_fresh.csv) for the held-out γ.
# Rerunning it skips finished runs and cells and resumes the others.
set -uo pipefail
cd "$(dirname "$0")/../../.."
bc_set() {  # task
    local env=$1 out=results/beyond/bc_train/$1
    python reproduce.py --preset continuous --envs "$env" --variants pgg_g1.1_bc0.1 --root runs/bc_train \
        --results "$out" --workers "${WORKERS:-2}" --compile &&
    cp runs/bc_train/sweep/evaluated_by.csv "$out/evaluated_by.csv" &&  # which file evaluated each agent
    python eval_gamma_sweep.py "$out/agents" --eval-seed 20000 --workers "${WORKERS:-2}" \
        --output "runs/sweeps/bc_train_fresh_$env" &&
    cp "runs/sweeps/bc_train_fresh_$env/episodes.csv" "$out/heldout_fresh.csv" &&
    cp "runs/sweeps/bc_train_fresh_$env/evaluated_by.csv" "$out/heldout_evaluated_by.csv" &&
    python -m paper_study.heldout_gamma "$out/episodes.csv" "$out/heldout_fresh.csv" --output "$out"
    echo "set $env: exit $? at $(date -u +%FT%TZ)"
}
tasks=("$@")
[ ${#tasks[@]} -gt 0 ] || tasks=(Hopper-v4 Walker2d-v4 Humanoid-v4)
for env in "${tasks[@]}"; do
    bc_set "$env"
done
