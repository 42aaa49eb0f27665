#!/usr/bin/env bash
# The behaviour-cloned null of the shipped agents (results/beyond/bc_null/README.md): the null embedding of
# each agent at its last step fitted to 40 of its own episodes (pgg_utils/bc_null.py), then swept at the
# paper's gamma (episode seeds 10000+, the baselines' episodes) and again on fresh episodes (20000+) for the
# held-out gamma. Rerunning it keeps the fitted checkpoints and finished cells.
set -euo pipefail
cd "$(dirname "$0")/../../.."
out=results/beyond/bc_null
for env in Hopper-v4 Walker2d-v4 Humanoid-v4; do
    for variant in ppo pgg_g1.1; do
        python -m pgg_utils.bc_null results/continuous/agents/"$env"__"$variant"__s{1,2,3,4,5} --steps 1000000 \
            --output "$out/agents"
    done
done
for env in CartPole-v1 Acrobot-v1; do
    for variant in ppo pgg_g1.1; do
        python -m pgg_utils.bc_null results/discrete/agents/"$env"__"$variant"__s{1,2,3,4,5} --steps 500000 \
            --output "$out/agents"
    done
done
for eval_seed in 10000 20000; do
    python eval_gamma_sweep.py "$out/agents" --eval-seed "$eval_seed" --workers "${WORKERS:-2}" \
        --output "runs/sweeps/bc_null_$eval_seed"
done
cp runs/sweeps/bc_null_10000/episodes.csv "$out/episodes.csv"
cp runs/sweeps/bc_null_20000/episodes.csv "$out/heldout_fresh.csv"
cp runs/sweeps/bc_null_10000/evaluated_by.csv "$out/evaluated_by.csv"  # which file evaluated each agent
cp runs/sweeps/bc_null_20000/evaluated_by.csv "$out/heldout_evaluated_by.csv"
python -m paper_study.heldout_gamma "$out/episodes.csv" "$out/heldout_fresh.csv" --null-branch bc --output "$out"
# The same agents with their own null on the fresh episodes at every γ (the tables' fresh sweeps hold only
# γ = 1 and the selected γ on some tasks): the other side of the report's fresh-episode tests.
python eval_gamma_sweep.py results/continuous/agents/{Hopper,Walker2d,Humanoid}-v4__{ppo,pgg_g1.1}__s{1,2,3,4,5} \
    results/discrete/agents/{CartPole,Acrobot}-v1__{ppo,pgg_g1.1}__s{1,2,3,4,5} --steps 500000 1000000 \
    --eval-seed 20000 --workers "${WORKERS:-2}" --output runs/sweeps/bc_null_own_20000
cp runs/sweeps/bc_null_own_20000/episodes.csv "$out/own_null_fresh.csv"
cp runs/sweeps/bc_null_own_20000/evaluated_by.csv "$out/own_null_evaluated_by.csv"
