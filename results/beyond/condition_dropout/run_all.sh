#!/usr/bin/env bash
# The sets of "Guidance on a condition, with the condition dropped in training" (results/beyond/README.md):
# classifier-free guidance's recipe on a condition, the condition's dimensions replaced by the null embedding
# with probability 0.1 in updates (--cond-dropout 0.1 with --null-dims), both branches trained at γ_train 1,
# guidance only at test. 5 seeds x 1M steps with --compile, checkpoints every 200k, as the sets beside them:
#   command/     HalfCheetah told how fast to run (paper_study/cheetah_velocity/, the command at index 17),
#                pgg_drop0.1_null17; swept at GAMMAS on commands from the training range (episode seeds 10000+),
#                fresh episodes for the held-out γ (20000+), then tracked at GAMMAS x COMMANDS (30000+) as
#                results/beyond/command was
#   Reacher-v4/  the goal dropped (pgg_drop0.1_goal); the paper's continuous γ list, fresh episodes, held-out γ,
#                and the final distance to the goal (goal_distance.csv) as the goal sets were
# Rerunning it skips finished runs, cells and checkpoints and resumes the others. It commits nothing: run it
# from a clean worktree of one commit. WORKERS (default 2) runs that many trainings and sweep workers at once.
set -uo pipefail
cd "$(dirname "$0")/../../.."
out=results/beyond/condition_dropout
workers=${WORKERS:-2}
cmd_env=paper_study.cheetah_velocity:HalfCheetahVelocity-v0
GAMMAS=(0.5 0.8 1 1.25 1.5 2 3)
COMMANDS=(-0.5 0 0.5 1 1.5 2 2.5 3)
python reproduce.py --preset continuous --envs "$cmd_env" --variants pgg_drop0.1_null17 --seeds "${SEEDS:-5}" \
    --root runs/condition_dropout/command --results "$out/command" --gammas "${GAMMAS[@]}" --workers "$workers" \
    --compile &&
cp runs/condition_dropout/command/sweep/evaluated_by.csv "$out/command/evaluated_by.csv"
echo "command set trained and swept: exit $? at $(date -u +%FT%TZ)"
python reproduce.py --preset continuous --envs Reacher-v4 --variants pgg_drop0.1_goal --seeds "${SEEDS:-5}" \
    --root runs/condition_dropout/reacher --results "$out/Reacher-v4" --workers "$workers" --compile &&
cp runs/condition_dropout/reacher/sweep/evaluated_by.csv "$out/Reacher-v4/evaluated_by.csv"
echo "Reacher set trained and swept: exit $? at $(date -u +%FT%TZ)"
python eval_gamma_sweep.py "$out/command/agents" --steps 1000000 --gammas "${GAMMAS[@]}" --eval-seed 20000 \
    --workers "$workers" --output runs/sweeps/condition_dropout_command_fresh &&
cp runs/sweeps/condition_dropout_command_fresh/episodes.csv "$out/command/heldout_fresh.csv" &&
cp runs/sweeps/condition_dropout_command_fresh/evaluated_by.csv "$out/command/heldout_evaluated_by.csv" &&
python -m paper_study.heldout_gamma "$out/command/episodes.csv" "$out/command/heldout_fresh.csv" --output "$out/command"
echo "command held-out γ: exit $? at $(date -u +%FT%TZ)"
python eval_gamma_sweep.py "$out/Reacher-v4/agents" --eval-seed 20000 --workers "$workers" \
    --output runs/sweeps/condition_dropout_reacher_fresh &&
cp runs/sweeps/condition_dropout_reacher_fresh/evaluated_by.csv "$out/Reacher-v4/heldout_evaluated_by.csv" &&
python -m paper_study.heldout_gamma "$out/Reacher-v4/episodes.csv" \
    runs/sweeps/condition_dropout_reacher_fresh/episodes.csv --output "$out/Reacher-v4"
echo "Reacher held-out γ: exit $? at $(date -u +%FT%TZ)"
python -m beyond.command_tracking "$out/command/agents" --steps 1000000 --gammas "${GAMMAS[@]}" \
    --commands "${COMMANDS[@]}" --episodes 50 --workers "$workers" --output "$out/command/tracking.csv"
echo "command tracking: exit $? at $(date -u +%FT%TZ)"
python -m beyond.goal_distance "$out/Reacher-v4/agents" --steps 1000000 --output "$out/goal_distance.csv"
echo "Reacher goal distance: exit $? at $(date -u +%FT%TZ)"
