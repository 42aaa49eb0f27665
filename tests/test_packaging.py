"""The project as a package and as a citation: a non-editable `pip install .` works from any folder and
leaves nothing git would show in the source tree; CITATION.cff holds to the Citation File Format 1.2.0
and cites the paper as the README does."""

import csv
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

NOT_PACKAGED = ("results/", "benchmarks/")  # the committed results and their tools: large, and no part of the wheel


def tracked_files() -> list[str]:
    if shutil.which("git") is None:
        pytest.skip("git is not installed: the packaging test copies the repository's tracked files")
    proc = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip("not a git checkout: the packaging test copies the repository's tracked files")
    return [path for path in proc.stdout.splitlines() if not path.startswith(NOT_PACKAGED)]


def build_backend_here() -> None:
    """`pip install --no-build-isolation` builds with this environment's setuptools, off the network;
    setuptools 70 is the first to build a wheel without the `wheel` package (the [dev] extra asks for it)."""
    try:
        from importlib.metadata import version

        major = int(version("setuptools").split(".")[0])
    except Exception:
        major = 0
    if major < 70:
        pytest.skip("needs setuptools>=70 (pip install -e '.[dev]') to build the wheel without the network")


@pytest.mark.slow
def test_a_non_editable_install_finds_the_papers_data_from_any_folder(tmp_path):
    """`pip install .` (not -e) of a copy of the repository, then a sweep of a committed agent and
    plot_results --compare-paper, each run as an installed module from a folder outside any source tree: it reads the paper's numbers from the
    installed package and tables the committed discrete sweep exactly as committed, with its provenance.
    Before the paper's CSVs were package data it stopped with `paper_study/data/paper_results.csv: No such
    file`; before build/ was ignored the install left it untracked in the tree; before --provenance looked
    beside its file, every cell's provenance read "?"."""
    build_backend_here()
    source, site, elsewhere = tmp_path / "source", tmp_path / "site", tmp_path / "elsewhere"
    for path in tracked_files():
        (source / path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / path, source / path)
    git = ["git", "-c", "core.hooksPath=/dev/null", "-C", str(source)]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index"]
    proc = subprocess.run([*pip, "--target", str(site), str(source)], capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr

    left = subprocess.run([*git, "status", "--porcelain", "--untracked-files=all"], capture_output=True, text=True)
    assert [line for line in left.stdout.splitlines() if line.startswith("??")] == []  # build/, pgg.egg-info/
    for name in ("paper_results.csv", "paper_dropout_figure.csv"):
        installed = site / "paper_study" / "data" / name
        assert installed.read_bytes() == (ROOT / "paper_study" / "data" / name).read_bytes()

    elsewhere.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site), "OMP_NUM_THREADS": "1"}
    locate = "import plot_results, paper_study.agreement as a; print(plot_results.__file__); print(a.PAPER_DATA)"
    where = subprocess.run([sys.executable, "-c", locate], cwd=elsewhere, env=env, capture_output=True, text=True)
    assert where.returncode == 0, where.stderr
    assert all(Path(line).is_relative_to(site) for line in where.stdout.split()), where.stdout  # not the source tree
    # The study past the paper (beyond/, the command task) stays in the repository.
    assert not (site / "beyond").exists() and not (site / "paper_study" / "cheetah_velocity").exists()
    checkpoint = ROOT / "results/discrete/agents/CartPole-v1__ppo__s1/checkpoints/step_000500000.pt"
    swept = subprocess.run([sys.executable, "-m", "eval_gamma_sweep", str(checkpoint), "--gammas", "1", "2",
                            "--episodes", "2", "--workers", "1", "--output", str(tmp_path / "sweep")],
                           cwd=elsewhere, env=env, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert swept.returncode == 0, swept.stderr
    (evaluated,) = list(csv.DictReader(open(tmp_path / "sweep" / "evaluated_by.csv")))
    assert evaluated["evaluated_by"] == "ppo_pgg_discrete.py", evaluated
    assert len(list(csv.DictReader(open(tmp_path / "sweep" / "episodes.csv")))) == 4
    out = tmp_path / "tables"
    plotted = subprocess.run([sys.executable, "-m", "plot_results", str(ROOT / "results" / "discrete"),
                              "--compare-paper", "--provenance", str(ROOT / "results" / "provenance.csv"),
                              "--output", str(out)],
                             cwd=elsewhere, env=env, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert plotted.returncode == 0, plotted.stderr
    for name in ("compare_paper.csv", "compare_paper_tasks.csv"):
        assert (out / name).read_bytes() == (ROOT / "results" / "discrete" / name).read_bytes(), name
    # The provenance's CSVs are found beside the provenance file, not in the installed package's folder.
    row = next(line for line in (out / "provenance.md").read_text().splitlines() if "discrete/episodes.csv" in line)
    committed = (ROOT / "results" / "discrete" / "provenance.md").read_text()
    assert row.split("|")[2:] == next(line for line in committed.splitlines() if "discrete/episodes.csv`" in line
                                      and "control" not in line).split("|")[2:]  # fmt: skip


def test_the_in_tree_build_folder_is_ignored():
    """`pip install .` in a clone writes build/ (setuptools' staging of the wheel) into it: ignored, never
    shown by `git status` as the user's own untracked work."""
    tracked_files()
    proc = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "-q", "build/lib/plot_results.py"])
    assert proc.returncode == 0


# The Citation File Format 1.2.0's rules (its schema.json) for the fields CITATION.cff uses; a field not listed
# here fails the test below until its rule is added from the schema.
CFF_REQUIRED = {"cff-version", "message", "title", "authors"}
CFF_FIELDS = {"cff-version", "message", "type", "title", "abstract", "authors", "license", "version",
              "date-released", "keywords", "preferred-citation", "references", "url", "repository-code", "doi"}  # fmt: skip
CFF_PERSON = {"family-names", "given-names", "name-particle", "name-suffix", "affiliation", "email", "orcid",
              "website", "alias"}  # fmt: skip
CFF_ENTITY = {"name", "email", "website", "orcid", "alias", "address", "city", "country"}
CFF_REFERENCE = {"type", "title", "authors", "year", "month", "notes", "url", "doi", "journal", "publisher",
                 "conference", "collection-title", "status", "abstract", "keywords", "version"}  # fmt: skip
CFF_REFERENCE_TYPES = {
    "art", "article", "audiovisual", "bill", "blog", "book", "catalogue", "conference-paper", "conference", "data",
    "database", "dictionary", "edited-work", "encyclopedia", "film-broadcast", "generic", "government-document",
    "grant", "hearing", "historical-work", "legal-case", "legal-rule", "magazine-article", "manual", "map",
    "multimedia", "music", "newspaper-article", "pamphlet", "patent", "personal-communication", "proceedings",
    "report", "serial", "slides", "software-code", "software-container", "software-executable",
    "software-virtual-machine", "software", "sound-recording", "standard", "statute", "thesis", "unpublished",
    "video", "website",
}  # fmt: skip
BIBTEX_OF_CFF = {"article": "article", "book": "book", "conference-paper": "inproceedings", "generic": "misc",
                 "report": "techreport", "thesis": "phdthesis", "unpublished": "unpublished"}  # fmt: skip


def cff_author_errors(where: str, authors) -> list[str]:
    if not isinstance(authors, list) or not authors:
        return [f"{where}: a non-empty list"]
    errors = []
    for i, author in enumerate(authors):
        keys = set(author) if isinstance(author, dict) else set()
        if "name" in keys:  # an entity
            errors += [f"{where}[{i}].{k}: not an entity's field" for k in sorted(keys - CFF_ENTITY)]
        elif not keys or keys - CFF_PERSON:
            errors.append(
                f"{where}[{i}]: neither a person ({sorted(keys - CFF_PERSON)} unknown) nor an entity (no name)"
            )
        errors += [f"{where}[{i}].{k}: an empty string" for k, v in author.items() if not (isinstance(v, str) and v)]
    return errors


def cff_errors(cff: dict) -> list[str]:
    """Where `cff` breaks CFF 1.2.0 in the fields it uses, and fields this check has no rule for."""
    errors = [f"{k}: required" for k in sorted(CFF_REQUIRED - set(cff))]
    errors += [f"{k}: no rule for this field here" for k in sorted(set(cff) - CFF_FIELDS)]
    if cff.get("cff-version") != "1.2.0":
        errors.append("cff-version: the string 1.2.0")
    if cff.get("type", "software") not in ("software", "dataset"):
        errors.append("type: software or dataset")
    if "date-released" in cff and not re.fullmatch(r"\d{4}-(0[1-9]|1[012])-(0[1-9]|[12]\d|3[01])",
                                                   str(cff["date-released"])):  # fmt: skip
        errors.append("date-released: YYYY-MM-DD")
    errors += cff_author_errors("authors", cff.get("authors"))
    for name in ("message", "title", "abstract", "version", "license"):
        if name in cff and not (isinstance(cff[name], str) and cff[name]):
            errors.append(f"{name}: a non-empty string")
    references = [("preferred-citation", cff["preferred-citation"])] if "preferred-citation" in cff else []
    references += [(f"references[{i}]", r) for i, r in enumerate(cff.get("references", []))]
    for where, reference in references:
        errors += [f"{where}.{k}: required" for k in ("type", "title", "authors") if k not in reference]
        errors += [f"{where}.{k}: no rule for this field here" for k in sorted(set(reference) - CFF_REFERENCE)]
        if reference.get("type") not in CFF_REFERENCE_TYPES:
            errors.append(f"{where}.type: not a CFF reference type")
        errors += cff_author_errors(f"{where}.authors", reference.get("authors"))
        if not isinstance(reference.get("year", 0), int) and not (
            isinstance(reference["year"], str) and reference["year"]
        ):
            errors.append(f"{where}.year: an integer or a non-empty string")
        for k in ("url",):
            if k in reference and not re.match(r"(https|http|ftp|sftp)://.+", reference[k]):
                errors.append(f"{where}.{k}: a URL")
    return errors


def test_the_cff_check_sees_what_the_schema_refuses():
    good = {"cff-version": "1.2.0", "message": "m", "title": "t", "authors": [{"name": "e"}]}
    assert cff_errors(good) == []
    assert cff_errors({**good, "cff-version": 1.2}) == ["cff-version: the string 1.2.0"]
    assert cff_errors({**good, "authors": [{"name": "e", "given-names": "x"}]}) == [
        "authors[0].given-names: not an entity's field"]  # fmt: skip
    assert cff_errors({**good, "date-released": "2026-13-01"}) == ["date-released: YYYY-MM-DD"]
    paper = {"type": "preprint", "title": "p", "authors": [{"family-names": "Qi"}], "year": 2025}
    assert cff_errors({**good, "preferred-citation": paper}) == ["preferred-citation.type: not a CFF reference type"]
    assert cff_errors({**good, "funding": "x"}) == ["funding: no rule for this field here"]


def test_citation_cff_holds_to_cff_1_2_0_and_cites_the_paper_as_the_readme_does():
    """CITATION.cff keeps CFF 1.2.0's rules for the fields it uses; its version is the package's and its
    licence LICENSE's; the software's author is an entity, not one of the paper's authors; and its preferred
    citation is the README's BibTeX entry: same title, authors in order, year, URL and entry type (a preprint
    is `generic`, BibTeX's @misc: an `article` needs a journal)."""
    yaml = pytest.importorskip("yaml", reason="pyyaml reads CITATION.cff (pip install -e '.[dev]')")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff_errors(cff) == []
    assert f'\nversion = "{cff["version"]}"\n' in (ROOT / "pyproject.toml").read_text()  # the package's ([project])
    assert (ROOT / "LICENSE").read_text().startswith(f"{cff['license']} License")

    paper = cff["preferred-citation"]
    assert all("name" in author for author in cff["authors"])  # the software's authors: an entity
    paper_authors = [f"{a['family-names']}, {a['given-names']}" for a in paper["authors"]]
    assert not {a["name"] for a in cff["authors"]} & {a["family-names"] for a in paper["authors"]}

    readme = (ROOT / "README.md").read_text().split("## Cite", 1)[1]
    entry = re.search(r"@(\w+)\{[^,]+,(.*?)\n\}", readme, flags=re.DOTALL)
    fields = dict(re.findall(r"(\w+)\s*=\s*\{(.*?)\},?\n", entry.group(2) + "\n"))
    assert entry.group(1) == BIBTEX_OF_CFF[paper["type"]]
    assert fields["title"] == paper["title"]
    assert fields["author"].split(" and ") == paper_authors
    assert int(fields["year"]) == paper["year"]
    assert fields["url"] == paper["url"]
