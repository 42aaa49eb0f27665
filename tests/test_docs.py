import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

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
    printed = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "results_at_a_glance.py")], capture_output=True,
                             text=True, check=True, timeout=120).stdout  # fmt: skip
    readme = (ROOT / "README.md").read_text()
    shown = readme.split("<!-- glance: python benchmarks/results_at_a_glance.py -->\n")[1].split("<!-- /glance -->")[0]
    assert shown == printed
    assert printed.count("\n") == 2 + 8  # a row per task of the paper's two tables


def test_readme_stays_a_front_page_with_the_ci_commands():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 220
    ci = (ROOT / ".ci" / "run").read_text()
    for command in ('pip install torch==2.13.0 && pip install -e ".[dev]" && python reproduce.py --preset quick',
                    "python -m pytest"):  # fmt: skip
        assert command in readme and command in ci


def test_the_readmes_trained_agent_snippet_runs():
    """The front page's "Use a trained agent" code, run as written, from the repository's root, on the
    shipped agent it names."""
    section = (ROOT / "README.md").read_text().split("## Use a trained agent", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, flags=re.DOTALL).group(1)
    seeded = "import torch\ntorch.manual_seed(0)\n" + code  # one sampled episode: a seed makes it this one
    proc = subprocess.run([sys.executable, "-c", seeded], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert float(proc.stdout.strip()) > 1000  # a trained Hopper at γ = 1.2 hops


NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?![\w.])")


def rounds_from(text: str, values: list[float]) -> bool:
    """Whether `text` (a number as written) is one of `values` rounded to as many decimals as it shows."""
    decimals = len(text.partition(".")[2])
    return any(abs(v - float(text)) <= 0.5 * 10**-decimals + 1e-9 for v in values)


def test_the_readmes_beyond_the_paper_numbers_come_from_its_report():
    """Each number in the README's "Beyond the paper" section rounds from one in results/beyond/report.md,
    so a report regenerated with other figures fails this until the front page follows. It cannot tell
    which cell a number came from: a figure quoted for the wrong variant passes where the report holds
    it elsewhere, and a small integer matches almost anything."""
    readme = (ROOT / "README.md").read_text()
    section = LINK.sub("", readme.split("## Beyond the paper\n", 1)[1].split("\n## ", 1)[0])  # paths are no figures
    reported = [float(x) for x in NUMBER.findall((ROOT / "results" / "beyond" / "report.md").read_text())]
    quoted = NUMBER.findall(section)
    assert len(quoted) > 10 and not rounds_from("123456.7", reported)
    assert not [x for x in quoted if not rounds_from(x, reported)]
