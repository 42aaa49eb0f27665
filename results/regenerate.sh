#!/usr/bin/env bash
# Every table, figure and report under results/ that is computed from committed data, written again in place
# (about 4 minutes on 2 cores). In a clean checkout `git status --short results/` then lists nothing: each of
# these files regenerates byte for byte.
#
# Not made here, as they need more than committed files: the agents, episodes, tracking, goal distances and
# learned nulls (training and sweeps; benchmarks/compare_revisions.py reruns each kind on tiny runs at two
# revisions), the learning curves (TensorBoard runs, not committed) and the held-out γ of the sets whose fresh
# episodes were not kept (results/beyond/<task>/ and condition_dropout/Reacher-v4/).
set -euo pipefail
cd "$(dirname "$0")/.."

tables() {  # folder [plot_results flags]: the tables, figures and the report against the paper of one set
    local folder=$1; shift
    python plot_results.py "$folder" --compare-paper --output "$folder" "$@" >/dev/null
}
heldout() {  # folder [flags]: the held-out γ of a set from its committed fresh episodes
    local folder=$1; shift
    python -m paper_study.heldout_gamma "$folder/episodes.csv" "$folder/heldout_fresh.csv" --output "$folder" "$@"
}

# The paper's tables and their controls (results/README.md).
for set in discrete continuous discrete_first continuous_first continuous_pusher continuous_device \
    continuous_humanoid_400k continuous_ip_dropout continuous_halfcheetah_avx2; do
    python plot_results.py results/$set/*episodes.csv --provenance results/provenance.csv --compare-paper \
        --output results/$set >/dev/null
done
T=results/continuous/episodes.csv
L="table (338e9f8 class)"
compare() {  # base episodes, its label, the set it controls, that set's label
    python -m paper_study.compare_sweeps "$1" "results/$3/episodes.csv" --labels "$2" "$4" \
        --output "results/$3/compare_table.md"
}
compare results/discrete/episodes.csv "$L" discrete_first "ebaab04–98ce1f9"
compare $T "$L" continuous_first "before 3f7c06b"
compare $T "$L" continuous_pusher "35e2042"
compare $T "MuJoCo 2.3.7 (table)" continuous_device "MuJoCo 3.1.6"
compare $T "$L" continuous_humanoid_400k "35e2042"
compare $T "$L" continuous_ip_dropout "cc458a3"
compare $T "table (338e9f8, first CPU)" continuous_halfcheetah_avx2 "retrain (e2a6cfc, AVX2)"
heldout results/discrete
python -m paper_study.heldout_gamma $T results/continuous/heldout_fresh.csv --output results/continuous
python -m paper_study.results_at_a_glance --output results/at_a_glance.md
python -m paper_study.data.read_dropout_figure ../shared/paper/fig_continuous_dropout0.1.png \
    --beside results/continuous/fig_continuous_pgg_drop0.1.png --output results/continuous/side_by_side_pgg_drop0.1.png \
    --ours $T --provenance results/provenance.csv --table results/continuous/compare_paper_figure.md >/dev/null

# Beyond the paper (results/beyond/README.md): each set's tables as reproduce.py wrote them, then the report.
for set in Hopper-v4 Pusher-v4 Reacher-v4 Walker2d-v4 Humanoid-v4 bc_train/Hopper-v4 bc_train/Walker2d-v4 \
    bc_train/Humanoid-v4 command condition_dropout/command condition_dropout/Reacher-v4; do
    tables results/beyond/$set
done
for set in bc_train/Hopper-v4 bc_train/Walker2d-v4 bc_train/Humanoid-v4 command condition_dropout/command; do
    heldout results/beyond/$set
done
heldout results/beyond/bc_null --null-branch bc
python -m beyond.report results/beyond --table $T >/dev/null
