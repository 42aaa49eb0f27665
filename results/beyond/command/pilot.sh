#!/usr/bin/env bash
# The command task's pilot (results/beyond/README.md, "Guidance on a command"): one seed, 200k steps, of PPO and
# of PGG γ_train 1.1 with the null on the command (dim 17), trained as the set will be (--compile), then
# tracked at a few γ and commands with beyond/command_tracking.py (5 episodes a cell, both marks). One seed and a
# fifth of the set's steps: it shows whether tracking is being learned, the trend, not a result.
set -uo pipefail
cd "$(dirname "$0")/../../.."
env=paper_study.cheetah_velocity:HalfCheetahVelocity-v0
pilot() {  # run name, flags...
    local name=$1; shift
    python ppo_pgg_continuous.py --env-id "$env" --seed 1 --total-timesteps 200000 --checkpoint-interval 100000 \
        --output-dir runs/command_pilot --run-name "$name" --torch-threads 1 --compile "$@" \
        > "runs/command_pilot/$name.log" 2>&1
    echo "pilot $name: exit $? at $(date -u +%FT%TZ)"
}
mkdir -p runs/command_pilot
pilot ppo --guidance 1 &
pilot pgg_g1.1_null17 --guidance 1.1 --null-dims 17 &
wait
python -m beyond.command_tracking runs/command_pilot/ppo runs/command_pilot/pgg_g1.1_null17 \
    --gammas 0.5 1 1.5 2 --commands 0 0.5 1 1.5 2 3 --episodes 5 --workers 2 --output runs/command_pilot/tracking.csv
