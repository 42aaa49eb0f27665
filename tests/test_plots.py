import csv
import re
import subprocess
import sys

import pytest

import eval_gamma_sweep as sweep
import plot_results as plots
from conftest import ROOT

# Per-seed mean returns of the synthetic sweep: (env, variant, step, eval γ) -> three seed means.
# Two episodes per seed, at mean ± 1. With means m, m+1, m+2 the summary is (m+1) ± t(.975,2)·1/√3 = ± 2.5.
SEED_MEANS = {
    ("CartPole-v1", "ppo", 100000, 1.0): [270, 271, 272],  # paper 270.6 ± 81.3: agrees
    ("CartPole-v1", "ppo", 200000, 1.0): [300, 301, 302],  # paper 456.6 ± 50.8: disagrees
    ("CartPole-v1", "pgg_g1.1", 100000, 1.0): [336, 337, 338],  # paper 337.8 ± 96.4: agrees
    ("CartPole-v1", "pgg_g1.1", 100000, 2.0): [100, 101, 102],  # paper 393.0 ± 132.1: disagrees
    ("CartPole-v1", "pgg_g1.1", 200000, 1.0): [466, 467, 468],  # paper 466.8 ± 27.5: agrees
    ("CartPole-v1", "pgg_g1.1", 200000, 2.0): [499, 500, 501],  # paper 500.0 ± 0.0: agrees
    ("Acrobot-v1", "ppo", 100000, 1.0): [-201, -200, -199],  # paper -111.3 ± 7.5: disagrees
    ("Acrobot-v1", "ppo", 200000, 1.0): [-86, -85, -84],  # paper -85.6 ± 3.1: agrees
    ("Acrobot-v1", "pgg_g1.1", 100000, 1.0): [-112, -111, -110],
    ("Acrobot-v1", "pgg_g1.1", 100000, 2.0): [-94, -93, -92],
    ("Acrobot-v1", "pgg_g1.1", 200000, 1.0): [-87, -86, -85],
    ("Acrobot-v1", "pgg_g1.1", 200000, 2.0): [-84, -83, -82],
}
DISAGREEING = {("CartPole-v1", "ppo", 200000, 1.0), ("CartPole-v1", "pgg_g1.1", 100000, 2.0),
               ("Acrobot-v1", "ppo", 100000, 1.0)}  # fmt: skip
HALF_WIDTH = 4.302653 / 3**0.5  # t_{0.975,2} · s / √n with s = 1, n = 3


@pytest.fixture
def sweep_dir(tmp_path):
    rows = []
    for (env, variant, step, gamma), means in SEED_MEANS.items():
        for seed, mean in enumerate(means, start=1):
            for episode, ret in enumerate([mean - 1, mean + 1]):
                rows.append({"env_id": env, "variant": variant, "run": f"{env}__{variant}__s{seed}", "seed": seed,
                             "train_guidance": 1.1 if variant != "ppo" else 1.0, "cond_dropout": 0.0, "step": step,
                             "global_step": step, "eval_guidance": gamma, "policy": "sample", "null_branch": "learned",
                             "episode": episode, "episode_seed": 10_000 + episode, "return": ret, "length": 1})  # fmt: skip
    sweep.write_csv_atomic(tmp_path / "sweep" / "episodes.csv", sweep.EPISODE_COLUMNS, rows)
    return tmp_path / "sweep"


def generate(sweep_dir, tmp_path, **kw):
    return plots.generate(plots.Args(sweeps=(str(sweep_dir),), output=str(tmp_path / "out"), **kw))


def test_tables_hold_expected_cells(sweep_dir, tmp_path):
    generate(sweep_dir, tmp_path)
    markdown = (tmp_path / "out" / "table_discrete.md").read_text().splitlines()
    assert markdown[2] == "| Method | Acrobot-v1 | CartPole-v1 |"
    section = markdown.index("| **100k Steps** | | |")
    assert markdown[section + 1] == f"| PPO | -200.0 ± {HALF_WIDTH:.1f} | 271.0 ± {HALF_WIDTH:.1f} |"
    assert markdown[section + 2] == "| pgg_g1.1 |  |  |"
    assert markdown[section + 4] == f"|   γ=2 | -93.0 ± {HALF_WIDTH:.1f} | 101.0 ± {HALF_WIDTH:.1f} |"
    latex = (tmp_path / "out" / "table_discrete.tex").read_text()
    assert f"\\quad $\\gamma=2$ & $-93.0 \\pm {HALF_WIDTH:.1f}$ & $101.0 \\pm {HALF_WIDTH:.1f}$ \\\\" in latex
    assert "\\multicolumn{3}{l}{\\textbf{200k Steps}} \\\\" in latex


def test_latex_is_well_formed(sweep_dir, tmp_path):
    generate(sweep_dir, tmp_path)
    latex = (tmp_path / "out" / "table_discrete.tex").read_text()
    begins, ends = re.findall(r"\\begin\{(\w+)\}", latex), re.findall(r"\\end\{(\w+)\}", latex)
    assert sorted(begins) == sorted(ends) == sorted(["document", "table", "tabular"])
    assert latex.count("{") == latex.count("}")
    tabular = latex.split("\\begin{tabular}{lcc}")[1].split("\\end{tabular}")[0]
    rows = [line for line in tabular.splitlines() if line.endswith("\\\\") and "multicolumn" not in line]
    assert rows and all(row.count("&") == 2 for row in rows)
    assert all(line.count("$") % 2 == 0 for line in tabular.splitlines())


def test_comparison_flags_exactly_the_disagreeing_cells(sweep_dir, tmp_path):
    generate(sweep_dir, tmp_path, compare_paper=True)
    with open(tmp_path / "out" / "compare_paper.csv") as f:
        rows = list(csv.DictReader(f))
    compared = {(r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"])): r["agrees"] for r in rows}
    paper_cells = {k for k in SEED_MEANS if k[1] == "ppo" or k[0] == "CartPole-v1" or k[1] == "pgg_g1.1"}
    assert set(compared) == paper_cells
    assert {k for k, agrees in compared.items() if agrees == "False"} == DISAGREEING
    assert "**3 disagree**" in (tmp_path / "out" / "compare_paper.md").read_text()


def test_figures_have_one_line_per_gamma_plus_ppo(sweep_dir, tmp_path):
    written = generate(sweep_dir, tmp_path)
    summary = sweep.summarise(plots.select_mode(plots.read_episodes([sweep_dir]), "sample", "learned"))
    fig = plots.figure_for_variant(summary, ["Acrobot-v1", "CartPole-v1"], "pgg_g1.1")
    for ax in fig.axes:
        lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]  # not error-bar caps
        assert [line.get_label() for line in lines] == ["PPO", "γ=1", "γ=2"]
        ppo, gamma1, gamma2 = lines
        assert ppo.get_color() == "black" and ppo.get_linestyle() == "-" and gamma2.get_linestyle() == "--"
        assert len(ax.collections) >= 3  # one CI band (and error bars) per line
    cartpole = [line for line in fig.axes[1].get_lines() if line.get_label() == "γ=2"][0]
    assert list(cartpole.get_ydata()) == [101.0, 500.0]
    for path in written:
        if path.suffix in (".png", ".pdf"):
            head = path.read_bytes()[:8]
            assert head.startswith(b"\x89PNG") or head.startswith(b"%PDF")
            assert 5_000 < path.stat().st_size < 5_000_000


def test_gamma_response_labels_exactly_the_swept_gammas(sweep_dir):
    summary = sweep.summarise(plots.select_mode(plots.read_episodes([sweep_dir]), "sample", "learned"))
    fig = plots.gamma_response(summary, ["CartPole-v1"], step=None)
    fig.canvas.draw()
    ax = fig.axes[0]
    assert ax.get_xscale() == "log"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["1", "2"]
    assert not [t.get_text() for t in ax.get_xticklabels(minor=True) if t.get_text()]


def test_aggregate_and_best_gamma(sweep_dir, tmp_path):
    generate(sweep_dir, tmp_path)
    best = list(csv.DictReader(open(tmp_path / "out" / "best_gamma.csv")))
    chosen = {(r["env_id"], r["variant"], r["step"]): float(r["best_eval_guidance"]) for r in best}
    assert chosen[("CartPole-v1", "pgg_g1.1", "100000")] == 1.0 and chosen[("Acrobot-v1", "pgg_g1.1", "100000")] == 2.0
    aggregate = list(csv.DictReader(open(tmp_path / "out" / "aggregate_iqm.csv")))
    row = next(r for r in aggregate if r["variant"] == "pgg_g1.1" and r["step"] == "200000" and r["eval_guidance"] == "2.0")
    assert float(row["iqm"]) == pytest.approx(1.0, abs=0.02)  # best cell in both envs at 200k
    assert float(row["ci_low"]) <= float(row["iqm"]) <= float(row["ci_high"])


def test_controls_table_puts_evaluation_modes_side_by_side(sweep_dir, tmp_path):
    with open(sweep_dir / "episodes.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["env_id"] == "CartPole-v1" and r["step"] == "100000"]
    uniform = [r | {"null_branch": "uniform", "return": float(r["return"]) + 10} for r in rows if r["variant"] == "ppo"]
    sweep.write_csv_atomic(tmp_path / "uniform.csv", sweep.EPISODE_COLUMNS, uniform)
    plots.generate(plots.Args(sweeps=(str(sweep_dir), str(tmp_path / "uniform.csv")), output=str(tmp_path / "out")))
    table = (tmp_path / "out" / "controls.md").read_text().splitlines()
    assert table[0] == "| env | variant | step | eval γ | sample, learned null | sample, uniform null |"
    assert table[2:] == [f"| CartPole-v1 | ppo | 100k | 1 | 271.0 ± {HALF_WIDTH:.1f} | 281.0 ± {HALF_WIDTH:.1f} |"]
    # the main tables still report the sampled, learned-null mode only
    assert f"| PPO | -200.0 ± {HALF_WIDTH:.1f} | 271.0 ± {HALF_WIDTH:.1f} |" in (tmp_path / "out" / "table_discrete.md").read_text()


@pytest.mark.parametrize(
    "setup,extra,message",
    [
        ("missing", [], "no sweep CSV"),
        ("empty", [], "is empty"),
        ("columns", [], "lacks columns"),
        ("foreign_env", ["--compare-paper"], "none of the swept envs"),
    ],
)
def test_bad_input_exits_with_one_line(tmp_path, setup, extra, message):
    target = tmp_path / "episodes.csv"
    if setup == "empty":
        target.write_text("")
    elif setup == "columns":
        target.write_text("a,b\n1,2\n")
    elif setup == "foreign_env":
        row = {c: 0 for c in sweep.EPISODE_COLUMNS} | {"env_id": "MyEnv-v0", "variant": "ppo", "policy": "sample",
                                                       "null_branch": "learned", "seed": 1}  # fmt: skip
        sweep.write_csv_atomic(target, sweep.EPISODE_COLUMNS, [row, row | {"seed": 2}])
    proc = subprocess.run([sys.executable, str(ROOT / "plot_results.py"), str(target), "--output", str(tmp_path / "o"), *extra],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2 and len(errors) == 1 and message in errors[0] and "Traceback" not in proc.stderr
