"""A run's configuration, built once (`Configuration`) from its script and its training arguments, for
training, resume, the sweep, the tables, the learning curves, reproduce and bc_null. It gives the run's
default directory name, its variant id, its label (the key runs are pooled by), what a resume compares,
and the columns a sweep writes. The label names the script where it is not the repository's own, every
argument that differs from its default (CleanRL's, frozen) and every argument CleanRL lacks with its value,
so a new argument in a script's `Args` keeps its runs apart with no table to extend; a fork's new
argument and a fork's script also name its default run directory. Plain Python: nothing of the paper study."""

import functools
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from pgg_utils import scripts
from pgg_utils.arguments import RUN_ONLY_ARGS, env_id_in_path

# Arguments the variant id names; the configuration label lists the other training arguments.
VARIANT_ARGS = frozenset({"guidance", "guidance_schedule", "guidance_final", "guidance_kl_target", "cond_dropout",
                          "null_dims", "null_bc_coef", "null_bc_route"})  # fmt: skip
# The observation dimensions of a task's goal, named `goal` in a variant (--null-dims), from gymnasium's
# documentation of the v4 observations: Reacher's target position (4, 5) and fingertip-minus-target
# vector (8, 9, 10); Pusher's goal position (20, 21, 22). Reacher draws its target anew each episode;
# Pusher's goal is the same in every episode (gymnasium's PusherEnv), so its goal null is a control.
GOAL_DIMS = {"Reacher-v4": (4, 5, 8, 9, 10), "Pusher-v4": (20, 21, 22)}


# PGG's arguments at the values that train PPO (a constant γ_train of 1, the whole observation nulled).
PPO_GUIDANCE = {"guidance": 1.0, "guidance_schedule": "constant", "guidance_final": None, "guidance_kl_target": None,
                "guidance_bounds": (1.0, 1.5), "cond_dropout": 0.0, "null_bc_coef": 0.0, "null_bc_route": "null"}  # fmt: skip
# The defaults labels are written against, by action space: CleanRL's for ppo.py and
# ppo_continuous_action.py (its `gamma` is our `discount`), with PGG's arguments at PPO, which the two
# training scripts' defaults equal (tests/test_extending.py). Frozen, as data: changing a script's
# default neither renames nor splits an experiment already run. An argument they lack (a fork's) is
# compared with its script's own default.
FROZEN_DEFAULTS = {
    "discrete": {
        "total_timesteps": 500_000, "learning_rate": 2.5e-4, "num_envs": 4, "num_steps": 128, "anneal_lr": True,
        "discount": 0.99, "gae_lambda": 0.95, "num_minibatches": 4, "update_epochs": 4, "norm_adv": True,
        "clip_coef": 0.2, "clip_vloss": True, "ent_coef": 0.01, "vf_coef": 0.5, "max_grad_norm": 0.5,
        "target_kl": None, **PPO_GUIDANCE,
    },
    "continuous": {
        "total_timesteps": 1_000_000, "learning_rate": 3e-4, "num_envs": 1, "num_steps": 2048, "anneal_lr": True,
        "discount": 0.99, "gae_lambda": 0.95, "num_minibatches": 32, "update_epochs": 10, "norm_adv": True,
        "clip_coef": 0.2, "clip_vloss": True, "ent_coef": 0.0, "vf_coef": 0.5, "max_grad_norm": 0.5,
        "target_kl": None, "obs_clip": 10.0, "reward_clip": 10.0, **PPO_GUIDANCE, "null_dims": None,
    },
}  # fmt: skip


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


def cloning_part(args: dict) -> str:
    """`` (no behaviour cloning by the null branch), `bc0.1` (--null-bc-coef 0.1), `bc0.1actor` (routed
    into the shared actor too)."""
    coef = float(args.get("null_bc_coef", 0.0))
    return f"bc{coef:g}{'actor' if args.get('null_bc_route', 'null') == 'actor' else ''}" if coef else ""


def variant_id(args: dict) -> str:
    """`ppo`, `pgg_g1.1`, `pgg_drop0.1`, `pgg_g1.1_drop0.1`, `pgg_g1to1.2`, `pgg_g1.1_goal`, `pgg_g1.1_bc0.1`,
    ...: a run's variant from its PGG arguments (those an older checkpoint lacks at their PPO values)."""
    guidance, dropout = guidance_part(args), float(args.get("cond_dropout", 0.0))
    parts = [] if guidance == "g1" else [guidance]
    parts += [f"drop{dropout:g}"] if dropout else []
    parts += [cloning_part(args)] if cloning_part(args) else []
    parts += [null_part(args)] if parts and null_part(args) else []  # null dims matter only where guidance does
    return "pgg_" + "_".join(parts) if parts else "ppo"


def normalised(value):
    return tuple(value) if isinstance(value, list) else value


def format_arg(value) -> str:
    if isinstance(value, (list, tuple)):
        return ",".join(format_arg(v) for v in value)
    return repr(value) if isinstance(value, float) else str(value)


# The label's fields that no training argument may be named (Configuration.label_fields).
LABEL_OWN_FIELDS = frozenset({"script", "null", "mujoco", "versions"})
# What the run directories of the repository's own scripts have always held after the env (run_stem).
ORIGINALS_EXPERIMENT = "ppo_pgg"
# What a run directory of a null embedding fitted after training (pgg_utils.bc_null) adds to its source run's name.
FITTED_NULL_SUFFIX = "__bcnull"


@dataclass(frozen=True)
class Configuration:
    """What a run is, built once from its script and its arguments (`of_checkpoint`, `of_run`), and all
    that is derived from it: `run_name`, `variant`, `label`, `key` (what runs are pooled by), `fields`
    (the sweep's columns) and `differing` (what a resume compares)."""

    kind: str
    """discrete or continuous, the action space its script trains"""
    script: str
    """its script as a checkpoint records it (scripts.script_name): a file name, or an absolute path"""
    args: dict
    """every argument, run-only ones included, with env_id"""
    null_fitted: bool = False
    """its null embedding was fitted after training (pgg_utils.bc_null), not trained"""
    versions: dict | None = field(default=None, compare=False)
    """the package versions that trained it; None: unknown (a format-1 checkpoint, or a run not yet trained)"""

    @classmethod
    def of_checkpoint(cls, ckpt: dict) -> "Configuration":
        return cls(ckpt.get("action_space"), scripts.script_name(ckpt), {"env_id": ckpt["env_id"], **ckpt["args"]},
                   bool(ckpt.get("null_fit")), ckpt.get("versions"))  # fmt: skip

    @classmethod
    def of_run(cls, script: str | Path, kind: str, args) -> "Configuration":
        """The configuration a training script `script` starts with `args` (its parsed `Args`)."""
        return cls(kind, scripts.recorded_path(Path(script)), asdict(args))

    @property
    def is_original(self) -> bool:
        """Whether the repository's own script for its action space trains it."""
        return self.script == f"{scripts.ORIGINALS.get(self.kind)}.py"

    @property
    def default_experiment(self) -> str:
        """--exp-name's default, what TensorBoard and W&B runs are grouped by: CleanRL's, the script's file
        stem, with the variant, so that it tells scripts and variants apart (`ppo_pgg_discrete__pgg_g1.1`,
        `ppo_relu__ppo`)."""
        return f"{Path(self.script).stem}__{self.variant}"

    @property
    def experiment(self) -> str:
        """--exp-name as given, or its default (default_experiment)."""
        return self.args.get("exp_name") or self.default_experiment

    @property
    def run_stem(self) -> str:
        """What the default run name holds after the env: --exp-name where one was given, else the script's
        file stem, and `ppo_pgg` for the repository's two scripts, the name their runs have always had."""
        given = self.args.get("exp_name")
        if given and given != self.default_experiment:
            return given
        return ORIGINALS_EXPERIMENT if self.is_original else Path(self.script).stem

    @property
    def variant(self) -> str:
        return variant_id(self.args)

    def new_arguments(self) -> dict:
        """The training arguments CleanRL's scripts lack (FROZEN_DEFAULTS), a fork's, with their values."""
        frozen = FROZEN_DEFAULTS.get(self.kind, {})
        skip = RUN_ONLY_ARGS | VARIANT_ARGS | {"env_id", "seed"} | frozen.keys()
        return {key: self.args[key] for key in sorted(self.args.keys() - skip)}

    def differing_arguments(self) -> dict[str, str]:
        """{name: value as the label writes it} for every training argument outside the variant that differs
        from its frozen default (FROZEN_DEFAULTS of its action space), and for every argument those lack (a
        fork's new one) whatever its value, sorted by name: two values of a fork's argument are two labels,
        whatever the fork's default was when each ran. One an older checkpoint lacks counts as the default."""
        args, defaults = self.args, FROZEN_DEFAULTS.get(self.kind, {})
        differing = {}
        for key in sorted((defaults.keys() | args.keys()) - RUN_ONLY_ARGS - VARIANT_ARGS - {"env_id", "seed"}):
            value = args.get(key, defaults.get(key))
            if key not in defaults or normalised(value) != normalised(defaults[key]):
                differing[key] = format_arg(value)
        return differing

    def label_fields(self) -> dict[str, str]:
        """What the label names after the variant, by name (label): `script`, `null`, each differing
        argument, and the stack (`mujoco` or `versions`). The sweep writes it as a column (`config_fields`,
        JSON), which its readers compare (config_fields), so that none parses a label back."""
        differing = self.differing_arguments()
        if clash := sorted(differing.keys() & LABEL_OWN_FIELDS):
            raise ValueError(f"an argument named {clash[0]} would hide the label's own field of that name; rename it")
        fields = {} if self.is_original else {"script": self.script}
        if self.null_fitted:
            fields["null"] = "bc"
        fields.update(differing)
        if not self.versions:
            fields["versions"] = "unknown"
        elif self.versions.get("mujoco") and is_mujoco(self.args["env_id"]):
            fields["mujoco"] = self.versions["mujoco"]
        return fields

    @property
    def label(self) -> str:
        """The configuration as a label, the key every reader pools runs by: its variant,
        `script=<file>` where a script other than the repository's own for its action space trained it,
        `null=bc` where its null embedding was fitted after training (pgg_utils.bc_null),
        every training argument that differs from its default (differing_arguments),
        then `mujoco=<version>` where the task runs on MuJoCo, or `versions=unknown` where the checkpoint
        records no package versions (format 1), so that it is never pooled with runs whose stack is known.
        Left out: env_id and seed (a table's rows and columns) and the run-only arguments. E.g. `pgg_g1.1
        learning_rate=0.002`, `ppo total_timesteps=50000 mujoco=2.3.7`, `pgg_g1.1 script=ppo_pgg_relu.py`."""
        return label_of(self.variant, self.label_fields())

    @property
    def run_name(self) -> str:
        """The default run directory name: `{env_id}__{run_stem}__g1.1__p0__s1`, with the schedule in place
        of `g1.1` (`g1to1.2`, `adaptive1.1_kl0.02`), `__goal` (or `__null4-5`) for partial null inputs,
        `__bc0.1` for behaviour cloning by the null branch and `__{name}{value}` for each argument a fork
        adds (new_arguments), so a fork and each value of its argument get a directory of their own;
        a namespaced id's ':' and '/' become '-' (arguments.env_id_in_path)."""
        args = self.args
        parts = [null_part(args), cloning_part(args), *(f"{k}{format_arg(v)}" for k, v in self.new_arguments().items())]
        extra = "".join(f"__{part}" for part in parts if part)
        return (f"{env_id_in_path(args['env_id'])}__{self.run_stem}__{guidance_part(args)}"
                f"__p{args.get('cond_dropout', 0.0):g}{extra}__s{args['seed']}")  # fmt: skip

    def fields(self) -> dict:
        """The columns of a sweep's rows that say which configuration a checkpoint is (`configuration` and
        `config_fields` read them back): its variant, its label, the label's fields (label_fields, as JSON),
        its γ_train (the first, for a schedule) and dropout."""
        variant, label_fields = self.variant, self.label_fields()
        return {"variant": variant, "config": label_of(variant, label_fields), "config_fields": json.dumps(label_fields),
                "train_guidance": float(self.args["guidance"]), "cond_dropout": float(self.args.get("cond_dropout", 0.0))}  # fmt: skip

    @property
    def key(self) -> tuple:
        """What runs are pooled by (`configuration`, the same key of a sweep's row)."""
        return configuration({"env_id": self.args["env_id"], **self.fields()})

    def training_arguments(self, script_defaults: dict) -> dict:
        """The arguments that decide what the run learns, by name: one this configuration lacks (an older
        checkpoint's) at its frozen default, or else at `script_defaults` (its script's `Args()`)."""
        frozen = FROZEN_DEFAULTS.get(self.kind, {})
        names = (self.args.keys() | script_defaults.keys()) - RUN_ONLY_ARGS
        return {name: self.args.get(name, frozen.get(name, script_defaults.get(name))) for name in sorted(names)}

    def differing(self, wanted: "Configuration", script_defaults: dict) -> list[str]:
        """What a resume compares: `script a -> b` where another script would continue this run, and
        `name recorded -> wanted` for each training argument in which `wanted` differs from it."""
        differing = (
            [] if Path(self.script).name == Path(wanted.script).name else [f"script {self.script} -> {wanted.script}"]
        )
        recorded, asked = self.training_arguments(script_defaults), wanted.training_arguments(script_defaults)
        return differing + [f"{name} {recorded[name]!r} -> {asked[name]!r}" for name in asked
                            if normalised(recorded.get(name)) != normalised(asked[name])]  # fmt: skip


def config_label(ckpt: dict) -> str:
    """A checkpoint's configuration label (Configuration.label)."""
    return Configuration.of_checkpoint(ckpt).label


def configuration_fields(ckpt: dict) -> dict:
    """A checkpoint's sweep columns (Configuration.fields)."""
    return Configuration.of_checkpoint(ckpt).fields()


def grid_run_name(env_id: str, variant: str, seed: int) -> str:
    """The name reproduce.py gives a run of its grid, `CartPole-v1__pgg_g1.1__s1` (the shipped agents'
    folders): the grid fixes the script and every other argument, so the variant and seed name it."""
    return f"{env_id_in_path(env_id)}__{variant}__s{seed}"


def run_of(ckpt: dict, path: str | Path) -> str:
    """The name of the run a checkpoint file belongs to, wherever it lies: the name it records, or, for a
    checkpoint from before it recorded one, its run directory's (`<run>/checkpoints/step_*.pt`)."""
    return ckpt.get("run") or Path(path).parent.parent.name


def label_of(variant: str, fields: dict) -> str:
    """A configuration's label from its variant and its label's fields (Configuration.label)."""
    return " ".join([variant, *(f"{name}={value}" for name, value in fields.items())])


def config_fields(row: dict) -> dict[str, str]:
    """What a row says its configuration's label names after the variant (Configuration.label_fields): its
    `config_fields` (JSON as a sweep writes it, or already read); a CSV written without that column (a sweep
    from before it, heldout_gamma.csv) has the label alone, whose `name=value` words are read instead (the
    one place a label is read back)."""
    value = row.get("config_fields")
    if isinstance(value, dict):
        return value
    if value:
        return json.loads(value)
    label = str(row.get("config") or row["variant"])
    return dict(word.split("=", 1) for word in label.split()[1:] if "=" in word)


def configuration(row: dict) -> tuple:
    """(env, variant, config, training guidance, dropout) of a sweep's row: the configuration its seeds
    pool over, exactly. The variant and config label alone round guidance and dropout to 6 digits
    (variant_id's %g). Rows of sweeps from before the config column count as their variant's."""
    config = str(row.get("config") or row["variant"])
    return (row["env_id"], row["variant"], config, float(row["train_guidance"]), float(row["cond_dropout"]))


@functools.cache
def is_mujoco(env_id: str) -> bool:
    """Whether the task runs on MuJoCo (its results then depend on the MuJoCo version)."""
    import gymnasium as gym

    try:
        entry_point = gym.spec(env_id).entry_point
    except gym.error.Error:
        return False
    return isinstance(entry_point, str) and entry_point.startswith("gymnasium.envs.mujoco")
