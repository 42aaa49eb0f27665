import csv
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, SCRIPTS, small_args, train

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "results" / "README.md",
         ROOT / "results" / "beyond" / "README.md", ROOT / "benchmarks" / "README.md"]  # fmt: skip
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def anchors(page: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation but hyphens dropped, spaces to hyphens."""
    found = set()
    for line in page.read_text().splitlines():
        if line.startswith("#") and not line.startswith("#!"):
            text = line.lstrip("#").strip().lower()
            found.add(re.sub(r"[^\w\- ]", "", text).replace(" ", "-"))
    return found


def relative_links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)  # code blocks hold no links
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    broken = []
    for target in relative_links(page):
        path, _, anchor = target.partition("#")
        resolved = (page.parent / path).resolve() if path else page
        if not resolved.exists():
            broken.append(f"{target}: no such file")
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
            broken.append(f"{target}: no heading with that anchor")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def test_the_link_check_sees_a_broken_link_and_a_missing_anchor(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# A heading, with `code`\n[ok](#a-heading-with-code) [gone](nothing.md) [bad](#nowhere)\n")
    assert relative_links(page) == ["#a-heading-with-code", "nothing.md", "#nowhere"]
    assert anchors(page) == {"a-heading-with-code"}


def test_readme_shows_the_glance_table_as_the_script_prints_it():
    printed = subprocess.run([sys.executable, "-m", "paper_study.results_at_a_glance"], capture_output=True,
                             text=True, check=True, timeout=120, cwd=ROOT).stdout  # fmt: skip
    readme = (ROOT / "README.md").read_text()
    shown = readme.split("<!-- glance: python -m paper_study.results_at_a_glance -->\n")[1].split("<!-- /glance -->")[0]
    assert shown == printed
    assert printed.count("\n") == 2 + 8  # a row per task of the paper's two tables


def test_readme_stays_a_front_page_with_the_ci_commands():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 240
    ci = (ROOT / ".ci" / "run").read_text()
    for command in ('pip install torch==2.13.0 && pip install -e ".[dev]" && python reproduce.py --preset quick',
                    "python -m pytest"):  # fmt: skip
        assert command in readme and command in ci


@pytest.mark.slow
def test_the_readmes_trained_agent_snippet_runs_and_prints_the_same_return_twice():
    """The front page's "Use a trained agent" code, run as written, twice, from the repository's root, on the
    shipped agent it names: `act` samples from torch's generator, so without the snippet's seed the two runs
    print different returns (3421.95, then 3297.78, before it had one)."""
    section = (ROOT / "README.md").read_text().split("## Use a trained agent", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, flags=re.DOTALL).group(1)
    printed = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        printed.append(proc.stdout)
    assert printed[0] == printed[1]
    assert float(printed[0].strip()) > 1000  # a trained Hopper at γ = 1.2 hops
    beside = section.split("```python", 1)[1].split("```", 1)[1].split("\n\n")[1]
    assert "samples" in beside and "without the seed" in beside  # the paragraph beside the code says why


@pytest.mark.slow
def test_the_test_count_the_pages_give_is_the_suites():
    """The "about N tests" of the front page and of docs/usage.md is within 10% of what pytest collects."""
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    collected = int(re.search(r"^(\d+) tests? collected", proc.stdout, flags=re.MULTILINE).group(1))
    for page in (ROOT / "README.md", ROOT / "docs" / "usage.md"):
        said = [int(n) for n in re.findall(r"about (\d+) tests", page.read_text())]
        assert said, f"{page.name} gives no test count"
        assert all(abs(n - collected) <= 0.1 * collected for n in said), (page.name, said, collected)


def bash_block(text: str, after: str) -> list[str]:
    """The commands of the first ```bash block after `after`, comments dropped."""
    block = text.split(after, 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    return [line.split("  #", 1)[0].strip() for line in block.splitlines() if line.strip()]


@pytest.mark.slow
def test_the_which_gamma_recipe_runs_on_a_tiny_cartpole_run(tmp_path):
    """The front page's three commands for choosing γ on a new task (the same as docs/usage.md's), run on two
    tiny CartPole seeds in place of runs/mytask, 5 episodes a cell: the held-out tool reports the γ chosen on
    the first sweep against γ = 1 on the second's fresh episodes."""
    readme = bash_block((ROOT / "README.md").read_text(), "**Which γ on a new task.**")
    assert readme == bash_block((ROOT / "docs" / "usage.md").read_text(), "### Which γ on a new task")
    for seed in (1, 2):
        train(SCRIPTS["discrete"], small_args("discrete", tmp_path / "runs" / "mytask", seed=seed, total_timesteps=512,
                                           checkpoint_interval=512, num_steps=128))  # fmt: skip
    for command in readme:
        program, *flags = command.split()
        assert program == "python"
        if flags[0] != "-m":
            flags[0] = str(ROOT / flags[0])
        if flags[0].endswith("eval_gamma_sweep.py"):
            flags += ["--episodes", "5"]
        proc = subprocess.run([sys.executable, *flags], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})  # fmt: skip
        assert proc.returncode == 0, f"{command}: {proc.stderr}"
    report = (tmp_path / "runs" / "heldout" / "heldout_gamma.md").read_text()
    assert "CartPole-v1" in report and "episode seeds 20000–20004" in report


@pytest.mark.slow
def test_the_custom_task_example_trains_as_written(tmp_path):
    """docs/usage.md's custom task, saved as the module it names, trains with the discrete script; its
    `__init__` takes `render_mode`, which every task is made with (one without it is refused before training)
    and which the README's pointer to the example names."""
    usage = (ROOT / "docs" / "usage.md").read_text()
    section = usage.split("### A custom task\n", 1)[1].split("\n## ", 1)[0]
    (tmp_path / "my_tasks.py").write_text(re.search(r"```python\n(.*?)```", section, flags=re.DOTALL).group(1))
    env_id = re.search(r"--env-id (\S+)`", section).group(1)
    proc = subprocess.run([sys.executable, str(ROOT / "ppo_pgg_discrete.py"), "--env-id", env_id, "--total-timesteps",
                           "512", "--num-steps", "128", "--output-dir", str(tmp_path / "runs")], cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(tmp_path)}, capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert list((tmp_path / "runs").glob("*/checkpoints/step_000000512.pt"))
    readme = (ROOT / "README.md").read_text()
    assert "render_mode" in readme and "(docs/usage.md#a-custom-task)" in readme


NUMBER = re.compile(r"(?<![\w.])<?\d+(?:\.\d+)?(?!\w|\.\d)")  # a number may end a sentence; `<0.001` a bound


def rounds_from(text: str, value: float) -> bool:
    """Whether `text` (a number as written, its sign left to the words) is `value` rounded to as many decimals
    as it shows: the rounding of the unrounded value, not of a figure already rounded (62.47 is 62, not 63);
    `<x` holds a value below x."""
    if text.startswith("<"):
        return abs(value) < float(text[1:])
    decimals = len(text.partition(".")[2])
    return abs(abs(value) - float(text)) < 0.5 * 10**-decimals + 1e-12


# The report_values.csv row (task, variant, baseline, quantity) of each number of the README's "Beyond the
# paper" section, in the order written; None for a label: a number of a variant's name or an eval γ.
H, W, U, P, R, A = "Hopper-v4", "Walker2d-v4", "Humanoid-v4", "Pusher-v4", "Reacher-v4", "Acrobot-v1"
LIN, ADA, CON, PPO, GOAL = "pgg_g1to1.2", "pgg_adaptive1.1_kl0.04", "pgg_g1.1", "ppo", "pgg_g1.1_goal"
BC = " null=bc"  # a behaviour-cloned null's rows (beyond/report.py)
CLONING = "pgg_g1.1_bc0.1"  # the variant that clones while it trains
FALL = "largest γ vs best (%)"
CMD, NULL17 = "paper_study.cheetah_velocity:HalfCheetahVelocity-v0", "pgg_g1.1_null17"  # the command task's set
DROP17, DROP_NULL, DROP_G1 = "pgg_drop0.1_null17", "condition dropout learned null", "condition dropout vs γ 1"
BEYOND_SOURCES = [
    (H, LIN, "", "seeds"),  # 5 seeds
    (U, LIN, PPO, "fall difference (pts)"), (U, LIN, PPO, "fall p Holm"),
    (U, LIN, PPO, "fall p Holm with the γ = 1 tests"), ("", "", "", "γ = 1 tests"), None,  # γ = 1
    None, None, (R, CON, "", "seeds farther"), (R, CON, "", "seeds"), (R, CON, "", "distance p Holm"),  # γ 1 to 1.5
    (W, PPO + BC, PPO, "fall difference (pts)"), (U, PPO + BC, PPO, "fall difference (pts)"),
    (W, PPO + BC, PPO, "fall p Holm"), (U, PPO + BC, PPO, "fall p Holm"),
    (A, PPO + BC, PPO, "fall difference (pts)"), (A, PPO + BC, PPO, "fall p"),
    (W, CLONING, PPO, "fresh fall difference (pts)"), (U, CLONING, PPO, "fresh fall difference (pts)"),
    (W, CLONING, PPO, "fresh fall p Holm"), None,  # γ_train 1.1
    (U, CLONING, CON, "fresh fall difference (pts)"), (U, CLONING, CON, "fresh fall p Holm"),
    None, None, None, (CMD, CON, "γ 1", "tracking error change at γ 1.25"),  # above 1: γ > 1, γ 1.25
    (CMD, CON, "γ 1", "tracking error p Holm at γ 1.25"),
    (CMD, NULL17, "γ 1", "tracking error above the range detectable at γ 1.25"),  # the least one test detects above
    (CMD, CON, "γ 1", "tracking error above the range detectable at γ 1.25"),  # the most
    (CMD, NULL17, "γ 1", "tracking error above the range change at γ 3"),
    (CMD, NULL17, "γ 1", "tracking error above the range p at γ 3"),
    (CMD, "", "command", "velocity at command 2 at γ 1"), None,  # below 1
    (CMD, NULL17, CON, "knob change at γ 0.5"), (CMD, NULL17, CON, "baseline's knob change at γ 0.5"),
    (CMD, NULL17, CON, "knob p Holm at γ 0.5"), (CMD, NULL17, "", "gain at γ 0.5"), (CMD, CON, "", "gain at γ 0.5"),
    None, (CMD, DROP17, DROP_NULL, "pseudo-command min"), (CMD, DROP17, DROP_NULL, "pseudo-command max"),  # γ > 1
    (CMD, NULL17, DROP_NULL, "pseudo-command min"), (CMD, NULL17, DROP_NULL, "pseudo-command max"),
    None, (CMD, DROP17, DROP_G1, "gain change at γ 1.5"), None, (CMD, DROP17, DROP_G1, "gain p Holm at γ 1.5"),
    (CMD, DROP17, DROP_G1, "tracking error change at γ 1.5"), (CMD, DROP17, DROP_G1, "tracking error p Holm at γ 1.5"),
    (CMD, DROP17, DROP_G1, "tracking error middle change at γ 1.5"),
    (CMD, DROP17, DROP_G1, "tracking error middle p Holm at γ 1.5"),
    None, None, ("Reacher-v4", "pgg_drop0.1_goal", "condition dropout", "final distance at γ 1"),  # the goal dropped
    ("Reacher-v4", "pgg_g1.1_goal", "condition dropout", "final distance at γ 1"),
    ("Reacher-v4", "pgg_g1.1", "condition dropout", "final distance at γ 1"), None, None, None,
    ("Reacher-v4", "pgg_drop0.1_goal", DROP_G1, "final distance change at γ 1.5"), None,
    ("Reacher-v4", "pgg_drop0.1_goal", DROP_G1, "final distance p Holm at γ 1.5"),
]  # fmt: skip


def beyond_numbers_unsupported(section: str, values: dict, labels: set[float]) -> list[str]:
    """The numbers of `section` that are not the rounding of the value BEYOND_SOURCES names for them."""
    quoted = NUMBER.findall(LINK.sub("", section))  # paths are no figures
    if len(quoted) != len(BEYOND_SOURCES):
        return [f"{len(quoted)} numbers, {len(BEYOND_SOURCES)} sources: {quoted}"]
    wrong = []
    for text, source in zip(quoted, BEYOND_SOURCES):
        if source is None and float(text) not in labels:
            wrong.append(f"{text}: no label")
        elif source is not None and not (source in values and rounds_from(text, values[source])):
            wrong.append(f"{text}: {source} is {values.get(source)}")
    return wrong


def test_the_readmes_beyond_the_paper_numbers_are_the_roundings_of_the_reports_values():
    """Each number in the README's "Beyond the paper" section is the correct rounding of the unrounded value
    (results/beyond/report_values.csv) it quotes, named in BEYOND_SOURCES: a report regenerated with other
    figures, a number rounded twice (from report.md's text) or quoted from the wrong cell fails here."""
    from paper_study.paper import paper_name
    from reproduce import PAPER_VARIANT_IDS, VARIANT_IDS

    with open(ROOT / "results" / "beyond" / "report_values.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    values = {(r["env_id"], r["variant"], r["baseline"], r["quantity"]): float(r["value"]) for r in rows}
    gammas = {float(m) for r in rows for m in re.findall(r"^return at γ ([\d.]+) at", r["quantity"])}
    names = " ".join(paper_name(v) for v in [*VARIANT_IDS[len(PAPER_VARIANT_IDS) :], "ppo", "pgg_g1.1"])
    labels = gammas | {float(x) for x in NUMBER.findall(names)}
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Beyond the paper\n", 1)[1].split("\n## ", 1)[0]
    assert not beyond_numbers_unsupported(section, values, labels)
    assert rounds_from("62", -62.47) and not rounds_from("63", -62.47) and not rounds_from("16", 15.48)
    assert rounds_from("<0.001", 6e-6) and not rounds_from("<0.001", 0.002)
