"""Rewrites shipped agents' metadata so that they name no folder of the machine that trained them, and proves
that nothing else changed (issue 51).

    python -m benchmarks.relocate_agents results              # rewrite, then compare every file with git HEAD's
    python -m benchmarks.relocate_agents results --check      # compare only

Checkpoints written since 2026-12-05 record `args.output_dir` relative to their run directory ("..") and the
run's name (`run`), so a copied checkpoint keeps both. The agents shipped before recorded the absolute output
folder of the training machine and no run name. For each `<run>/checkpoints/step_*.pt` under the given folders
this sets `args.output_dir` to ".." and `run` to `<run>` (where the checkpoint records neither already) and
writes the file with the project's own writer (pgg_utils.checkpoints.checkpoint_bytes: pickle-free, proven
readable). Then every rewritten file is compared with the version git holds at HEAD, field by field, with
compare_revisions' comparison (tensors with torch.equal, dtypes and shapes included): the only differences
allowed are those two fields. Exit status 0 when that holds for every file, 1 otherwise.
"""

import io
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro

from benchmarks.compare_revisions import compare_values
from pgg_utils.checkpoints import checkpoint_bytes, read_checkpoint_file
from pgg_utils.files import write_atomic

REWRITTEN = ("args.output_dir", "run")


@dataclass
class Args:
    folders: tyro.conf.Positional[tuple[str, ...]]
    """folders holding shipped agents (`<run>/checkpoints/step_*.pt`), searched recursively"""
    check: bool = False
    """compare with git HEAD only; rewrite nothing"""


def relocated(ckpt: dict, run: str) -> dict:
    """The checkpoint with its output folder relative to its run directory and its run's name recorded."""
    return {**ckpt, "args": {**ckpt["args"], "output_dir": ".."}, "run": ckpt.get("run") or run}


def committed(path: Path) -> dict:
    """The checkpoint as git holds it at HEAD."""
    data = subprocess.run(["git", "show", f"HEAD:{path.as_posix()}"], capture_output=True, check=True).stdout
    return torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)


def main() -> int:
    args = tyro.cli(Args, description=__doc__)
    paths = sorted(p for folder in args.folders for p in Path(folder).rglob("checkpoints/step_*.pt"))
    rewritten, unexpected = 0, {}
    for path in paths:
        ckpt = read_checkpoint_file(path)
        new = relocated(ckpt, path.parent.parent.name)
        if not args.check and new != ckpt:
            write_atomic(path, checkpoint_bytes(new))
            rewritten += 1
        differences, added = [], []
        compare_values(committed(path), read_checkpoint_file(path), path.as_posix(), differences, added)
        others = [d for d in differences if not d.split(": ")[0].endswith(".args.output_dir")]
        others += [f"{a}: new" for a in added if not a.endswith(".run")]
        if others:
            unexpected[path] = others
    print(
        f"{len(paths)} checkpoints, {rewritten} rewritten; {len(paths) - len(unexpected)} identical to git HEAD's "
        f"in every tensor and field but {' and '.join(REWRITTEN)}, {len(unexpected)} not"
    )
    for path, others in list(unexpected.items())[:20]:
        print(f"  {path}: {others[0]}")
    return 1 if unexpected else 0


if __name__ == "__main__":
    sys.exit(main())
