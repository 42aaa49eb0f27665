"""The agents a grid ships beside its tables (reproduce.py --agents): every checkpoint of its runs without the optimizer
and resume state, in the sweep's layout, with a README listing the command that trained each; a later export removes
only the agents an earlier one wrote."""

import contextlib
import sys
from pathlib import Path

from pgg_utils import checkpoints
from pgg_utils.files import read_manifest, remove_stale, write_atomic, write_manifest

README_HEADER = "| run | env | variant | seed | steps | trained by |"


def export_agents(specs: list, folder: Path) -> Path:
    """Every checkpoint of `specs` (reproduce.RunSpec) as a shipped agent, in the sweep's layout
    (<folder>/<run>/checkpoints/step_*.pt, so that eval_gamma_sweep.py sweeps the folder with the runs'
    own names), and <folder>/README.md listing them with the command that trained each. The folder holds
    the agents of the tables beside it: those an earlier export wrote (listed in its outputs.txt, or runs
    its README lists) that this one does not are removed (drop_stale_agents). Returns the README's path."""
    readme = folder / "README.md"
    earlier = read_manifest(folder)
    listed_in_readme = {str(path.relative_to(folder)) for name in readme_rows(readme)
                        for path in checkpoints.checkpoints_of(folder / name)} - earlier.keys()  # fmt: skip
    rows, exported = {}, set()
    for spec in specs:
        saved = checkpoints.checkpoints_of(spec.run_dir)
        for checkpoint in saved:
            checkpoints.export_agent(checkpoint, folder / spec.name / "checkpoints" / checkpoint.name)
            exported.add(f"{spec.name}/checkpoints/{checkpoint.name}")
        steps = ", ".join(f"{checkpoints.checkpoint_step(c):,}" for c in saved)
        command = " ".join(["python", Path(spec.command()[1]).name, *spec.command()[2:]])
        rows[spec.name] = f"| {spec.name} | {spec.env_id} | {spec.variant} | {spec.seed} | {steps} | `{command}` |"
    write_atomic(readme, "\n".join([
        "# Trained agents",
        "",
        "Each file is one checkpoint's agent: the weights (with the observation statistics), the training",
        "arguments, the software versions and the code revision, without the optimizer and resume state;",
        "pickle-free (`torch.load(path, weights_only=True)`). Sweep them with",
        f"`python eval_gamma_sweep.py {folder} --output runs/sweeps/agents` (add `--gammas ...` for your own",
        "γ values), watch one with `--video`, load one with `ppo_pgg_<kind>.load_checkpoint(path)`.",
        "",
        README_HEADER,
        "|---|---|---|---|---|---|",
        *rows.values(),
        "",
    ]))  # fmt: skip
    stale = {name: digest for name, digest in earlier.items() if name not in exported}
    drop_stale_agents(folder, stale, listed_in_readme - exported)
    write_manifest(folder, exported, "reproduce.py")
    return readme


def drop_stale_agents(folder: Path, listed: dict[str, str | None], in_readme: set[str]) -> None:
    """Removes the agents an earlier export wrote: those its manifest lists, where they are still what it wrote
    (files.remove_stale: only files inside `folder`), and those of an export before manifests, which only its
    README lists, where each is the agent of the run it is filed under (exported_agent); then each run folder
    they leave empty, with a note per run. Any other file is kept."""
    removed, _ = remove_stale(folder, listed)
    for name in sorted(in_readme):
        if exported_agent(folder / name):
            (folder / name).unlink()
            removed.append(folder / name)
    for run in sorted({Path(path).relative_to(folder).parts[0] for path in removed}):
        for empty in (folder / run / "checkpoints", folder / run):
            with contextlib.suppress(OSError):  # a file of the user's keeps its folder
                empty.rmdir()
        print(f"note: removed the agents of {run} from {folder}: this grid's tables do not hold it", file=sys.stderr)


def exported_agent(path: Path) -> bool:
    """Whether `path` (<folder>/<run>/checkpoints/step_*.pt) is an agent export_agents wrote: a checkpoint without
    resume state, of the run whose folder holds it (or of a version that did not record runs)."""
    try:
        agent = checkpoints.read_checkpoint_file(path)
    except (ValueError, OSError):
        return False
    return "resume" not in agent and agent.get("run", path.parent.parent.name) == path.parent.parent.name


def readme_rows(readme: Path) -> dict[str, str]:
    """{run name: its table row} of an agents README that export_agents wrote; {} where there is none."""
    if not readme.exists():
        return {}
    lines = readme.read_text().splitlines()
    if README_HEADER not in lines:
        return {}
    table = lines[lines.index(README_HEADER) + 2 :]
    return {row.split(" | ")[0].removeprefix("| "): row for row in table if row.startswith("| ")}
