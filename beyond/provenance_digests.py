"""Which committed code trained each agent of "Beyond the paper": every checkpoint's `code` field (the commit it
was trained at, whether its files were modified, the digest of the training script and pgg_utils/*.py) against
the digest each commit of this repository gives (pgg_utils.scripts.code_revision's recipe, recomputed from git):

    python -m beyond.provenance_digests results/beyond/*-v4/agents results/beyond/bc_train/*/agents \\
        results/beyond/command/agents > results/beyond/provenance/digests.txt

(bc_null/agents are the tables' agents with a fitted null: their training is the tables', results/README.md.)

One line per (set, seeds, digest): the commits it was trained at, the machine, and the commits whose files give
that digest ("none" where no commit does: code known by its digest alone); for such a digest, the commits whose
training script has the recorded script sha1.
"""

import hashlib
import subprocess
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import tyro

ROOT = Path(__file__).resolve().parents[1]
from pgg_utils import checkpoints


def git(*args: str) -> str:
    """git's output, empty where it fails (a commit without pgg_utils/: its digest is the script's alone)."""
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True).stdout


def commit_digests(script: str) -> tuple[dict, dict]:
    """({digest: [commits]}, {script sha1: [commits]}) over every commit that holds `script` and pgg_utils/."""
    batch = subprocess.Popen(["git", "-C", str(ROOT), "cat-file", "--batch"], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE)  # fmt: skip

    def blob(spec: str) -> bytes | None:
        batch.stdin.write(spec.encode() + b"\n")
        batch.stdin.flush()
        header = batch.stdout.readline().split()
        if header[1] == b"missing":
            return None
        data = batch.stdout.read(int(header[2]))
        batch.stdout.read(1)
        return data

    digests, scripts = defaultdict(list), defaultdict(list)
    for commit in git("rev-list", "--all", "--date-order").split():
        source = blob(f"{commit}:{script}")
        if source is None:
            continue
        names = sorted(n for n in git("ls-tree", "--name-only", f"{commit}:pgg_utils").split() if n.endswith(".py"))
        files = [source, *(blob(f"{commit}:pgg_utils/{name}") for name in names)]
        digests[hashlib.sha1(b"".join(files)).hexdigest()].append(commit[:7])
        scripts[hashlib.sha1(source).hexdigest()].append(commit[:7])
    batch.stdin.close()
    batch.wait()
    return digests, scripts


@dataclass
class Args:
    folders: tyro.conf.Positional[tuple[str, ...]]
    """the agents folders whose checkpoints to trace (results/beyond/<set>/agents)"""


def main() -> None:
    folders = tyro.cli(Args).folders
    groups = defaultdict(lambda: {"seeds": set(), "commits": set(), "machines": set(), "scripts": set()})
    for folder in folders:
        for path in checkpoints.find_checkpoints([folder]):
            ckpt = checkpoints.read_checkpoint_file(path)
            code = ckpt.get("code", {})
            key = (str(Path(folder).resolve().parent.relative_to(ROOT / "results")), ckpt["env_id"], ckpt["args"].get("seed"),
                   code.get("sha1", "?"), code.get("script", ckpt.get("script_path", "ppo_pgg_continuous.py")))  # fmt: skip
            group = groups[key]
            group["commits"].add(f"{code.get('commit', '?')[:7]}{' (modified)' if code.get('modified') else ''}")
            group["machines"].add(ckpt.get("machine") or "not recorded")
            group["scripts"].add(code.get("script_sha1", ""))
    by_digest = defaultdict(list)
    for (folder, env, seed, digest, script), group in sorted(groups.items(), key=lambda kv: str(kv[0])):
        by_digest[(folder, env, digest, script, tuple(sorted(group["commits"])), tuple(sorted(group["machines"])),
                   tuple(sorted(group["scripts"])))].append(seed)  # fmt: skip
    known = {}
    for (folder, env, digest, script, commits, machines, script_sha1s), seeds in sorted(by_digest.items()):
        if script not in known:
            known[script] = commit_digests(script)
        digests, scripts = known[script]
        matches = digests.get(digest, [])
        line = (
            f"{folder} {env} seeds {','.join(map(str, sorted(seeds)))}: digest {digest[:7]}, trained at "
            f"{', '.join(commits)}, on {'; '.join(machines)}; the digest of commits: {' '.join(matches) or 'none'}"
        )
        if not matches:
            by_script = sorted({c for s in script_sha1s if s for c in scripts.get(s, [])})
            line += f"; its script (sha1 {', '.join(s[:7] for s in script_sha1s if s) or '?'}) is that of commits: "
            line += " ".join(by_script) or "none"
        print(line)


if __name__ == "__main__":
    main()
