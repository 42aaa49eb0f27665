#!/usr/bin/env bash
# Pilot of the training variant that clones the rollout's actions by the null branch (--null-bc-coef,
# --null-bc-route): Hopper-v4, γ_train 1.1, seed 1, 300k steps, with --compile, for each coefficient and
# route; then each run's last checkpoint swept at γ 1, 1.2 and 1.5 (20 episodes). The figures: pilot.txt.
set -uo pipefail
cd "$(dirname "$0")/../../.."
train() {  # coefficient, route
    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1.1 --null-bc-coef "$1" --null-bc-route "$2" \
        --total-timesteps 300000 --checkpoint-interval 100000 --compile --output-dir runs/bc_pilot \
        --run-name "Hopper-v4__bc$1$2__s1" --resume > "runs/bc_pilot_$1$2.log" 2>&1
}
mkdir -p runs/bc_pilot
train 0.1 null & train 1 null & wait
train 0.1 actor & train 1 actor & wait
train 0 null  # no cloning: the constant γ_train 1.1 itself, the pilot's baseline
python eval_gamma_sweep.py runs/bc_pilot --steps 300000 --gammas 1 1.2 1.5 --episodes 20 --workers 2 \
    --output runs/sweeps/bc_pilot
python -m beyond.bc_train_pilot runs/bc_pilot runs/sweeps/bc_pilot/episodes.csv > results/beyond/bc_train/pilot.txt
