"""A run's identity, from its training arguments alone: its variant id, the paper's name for it, the
label of its configuration, its default run directory name, and the paper's table rows it is compared
with (pgg_utils.agreement reads them from the variant through the same pgg_utils.paper.paper_rows). A
new training argument is named in every label at once, or tests/test_extending.py says which table of
pgg_utils.paper to extend."""

from dataclasses import dataclass

from pgg_utils.arguments import env_id_in_path
from pgg_utils.paper import GOAL_DIMS, REFERENCE_ARGS, is_mujoco, paper_name, paper_rows

# Arguments the variant id names; the configuration label lists the other training arguments that
# differ from the frozen reference.
VARIANT_ARGS = frozenset({"guidance", "guidance_schedule", "guidance_final", "guidance_kl_target", "cond_dropout",
                          "null_dims"})  # fmt: skip


@dataclass(frozen=True)
class RunIdentity:
    variant: str  # e.g. ppo, pgg_g1.1, pgg_drop0.1, pgg_g1to1.2, pgg_adaptive1.1_kl0.02, pgg_g1.1_goal
    name: str  # the paper's name of the variant, or a readable one for variants the paper did not run
    label: str  # the variant and every other training argument that differs from the frozen reference
    train_guidance: float  # γ_train at the first iteration (constant throughout for the paper's variants)
    cond_dropout: float
    paper_rows: tuple[str, str] | None  # (method, γ_train) of the paper's table rows it is compared with


def guidance_part(args: dict) -> str:
    """`g1.1` (constant), `g1to1.2` (linear), `adaptive1.1_kl0.02` (adaptive)."""
    schedule = args.get("guidance_schedule", "constant")
    if schedule == "linear":
        return f"g{args['guidance']:g}to{args['guidance_final']:g}"
    if schedule == "adaptive":
        return f"adaptive{args['guidance']:g}_kl{args['guidance_kl_target']:g}"
    return f"g{args['guidance']:g}"


def null_part(args: dict) -> str:
    """`` (the null embedding replaces the whole observation), `goal` (the task's goal dimensions,
    GOAL_DIMS), else `null` and the dimensions, e.g. `null4-5`."""
    dims = None if args.get("null_dims") is None else sorted(args["null_dims"])  # a mask: order means nothing
    if dims is None:
        return ""
    if tuple(dims) == GOAL_DIMS.get(args.get("env_id")):
        return "goal"
    return "null" + "-".join(str(d) for d in dims)


def variant_id(args: dict) -> str:
    """`ppo`, `pgg_g1.1`, `pgg_drop0.1`, `pgg_g1.1_drop0.1`, `pgg_g1to1.2`, `pgg_g1.1_goal`, ...: a run's
    variant from its PGG arguments (those an older checkpoint lacks at their reference values)."""
    guidance, dropout = guidance_part(args), float(args.get("cond_dropout", 0.0))
    parts = [] if guidance == "g1" else [guidance]
    parts += [f"drop{dropout:g}"] if dropout else []
    parts += [null_part(args)] if parts and null_part(args) else []  # null dims matter only where guidance does
    return "pgg_" + "_".join(parts) if parts else "ppo"


def training_words(args: dict, kind: str) -> list[str]:
    """`key=value` for every training argument outside the variant that differs from the frozen
    reference of `kind`, sorted by name; those an older checkpoint lacks count as the reference's."""
    reference, words = REFERENCE_ARGS[kind], []
    for key in sorted(reference.keys() - VARIANT_ARGS):
        value = args.get(key, reference[key])
        if normalised(value) != normalised(reference[key]):
            words.append(f"{key}={format_arg(value)}")
    return words


def normalised(value):
    return tuple(value) if isinstance(value, list) else value


def format_arg(value) -> str:
    if isinstance(value, (list, tuple)):
        return ",".join(format_arg(v) for v in value)
    return repr(value) if isinstance(value, float) else str(value)


def run_identity(args: dict, kind: str) -> RunIdentity:
    """The identity of a run from its training arguments (a checkpoint's `args`, or `asdict(args)`)."""
    variant, words = variant_id(args), training_words(args, kind)
    return RunIdentity(
        variant=variant,
        name=paper_name(variant),
        label=" ".join([variant, *words]),
        train_guidance=float(args["guidance"]),
        cond_dropout=float(args.get("cond_dropout", 0.0)),
        paper_rows=paper_rows(variant),
    )


def run_name(args) -> str:
    """The default run directory name: `{env_id}__{exp_name}__g1.1__p0__s1`, with the schedule in place
    of `g1.1` (`g1to1.2`, `adaptive1.1_kl0.02`) and `__goal` (or `__null4-5`) for partial null inputs;
    a namespaced id's ':' and '/' become '-' (arguments.env_id_in_path)."""
    values = vars(args)
    null = f"__{null_part(values)}" if null_part(values) else ""
    return f"{env_id_in_path(args.env_id)}__{args.exp_name}__{guidance_part(values)}__p{args.cond_dropout:g}{null}__s{args.seed}"


def config_label(ckpt: dict) -> str:
    """The training configuration of a checkpoint, as a readable label: the run's identity label, then
    `mujoco=<version>` where the task runs on MuJoCo, or `versions=unknown` where the checkpoint records
    no package versions (format 1), so that it is never pooled with runs whose stack is known. Against
    frozen data (REFERENCE_ARGS), not the training scripts' current defaults: changing a default
    neither renames nor splits an experiment. Arguments the reference lacks (env_id, seed, how the run
    was recorded) are left out, and so is the revision of the training code, which changes with every
    commit. E.g. `pgg_g1.1 learning_rate=0.002`, `ppo total_timesteps=50000 mujoco=2.3.7`."""
    words = [run_identity({"env_id": ckpt["env_id"], **ckpt["args"]}, ckpt["action_space"]).label]
    versions = ckpt.get("versions")
    if not versions:
        words.append("versions=unknown")
    elif versions.get("mujoco") and is_mujoco(ckpt["env_id"]):
        words.append(f"mujoco={versions['mujoco']}")
    return " ".join(words)
