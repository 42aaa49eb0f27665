#!/usr/bin/env bash
# The command task's set ("Guidance on a command", results/beyond/README.md): HalfCheetah told each episode
# how fast to run (paper_study/cheetah_velocity/, commands drawn from [0, 2] m/s, the command at index 17).
# 5 seeds x 1M steps with --compile, checkpoints every 200k, of PPO, PGG γ_train 1.1 with the null on the
# command (pgg_g1.1_null17) and PGG γ_train 1.1 with the paper's whole-state null (pgg_g1.1); swept at GAMMAS
# with 50 episodes per cell on commands drawn from the training range (episode seeds 10000+); the last mark
# swept again on fresh episodes (20000+, committed as heldout_fresh.csv) for the held-out γ; then every last
# agent tracked at GAMMAS x COMMANDS, inside and outside the training range (beyond/command_tracking.py,
# 50 episodes per cell, seeds 30000+), and the report. Rerunning it skips finished runs, cells and
# checkpoints and resumes the others. It commits nothing: run it from a clean worktree of one commit.
# SEEDS=1 trains seed 1 alone (a go/no-go on whether 1M steps learn to track); the later full run resumes it.
set -uo pipefail
cd "$(dirname "$0")/../../.."
env=paper_study.cheetah_velocity:HalfCheetahVelocity-v0
out=results/beyond/command
workers=${WORKERS:-2}
GAMMAS=(0.5 1 1.25 1.5 2 3)
COMMANDS=(-0.5 0 0.5 1 1.5 2 2.5 3)
python reproduce.py --preset continuous --envs "$env" --variants ppo pgg_g1.1_null17 pgg_g1.1 --seeds "${SEEDS:-5}" --root runs/command \
    --results "$out" --gammas "${GAMMAS[@]}" --workers "$workers" --compile &&
cp runs/command/sweep/evaluated_by.csv "$out/evaluated_by.csv"
echo "set trained and swept: exit $? at $(date -u +%FT%TZ)"
python eval_gamma_sweep.py "$out/agents" --steps 1000000 --gammas "${GAMMAS[@]}" --eval-seed 20000 \
    --workers "$workers" --output runs/sweeps/command_fresh &&
cp runs/sweeps/command_fresh/episodes.csv "$out/heldout_fresh.csv" &&
cp runs/sweeps/command_fresh/evaluated_by.csv "$out/heldout_evaluated_by.csv" &&
python -m paper_study.heldout_gamma "$out/episodes.csv" "$out/heldout_fresh.csv" --output "$out"
echo "held-out γ: exit $? at $(date -u +%FT%TZ)"
python -m beyond.command_tracking "$out/agents" --steps 1000000 --gammas "${GAMMAS[@]}" \
    --commands "${COMMANDS[@]}" --episodes 50 --workers "$workers" --output "$out/tracking.csv"
echo "tracking: exit $? at $(date -u +%FT%TZ)"
python -m beyond.report results/beyond --table results/continuous/episodes.csv
