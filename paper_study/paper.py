"""The paper's experiment, written down once: its tasks, variants, swept γ values, and the training
defaults that name a configuration. Plain data and a few rules; no torch."""

import functools

from pgg_utils.arguments import DEFAULT_GAMMAS
from pgg_utils.identity import GOAL_DIMS, config_fields

PAPER_ENVS = {
    "discrete": ("Acrobot-v1", "CartPole-v1"),
    "continuous": ("HalfCheetah-v4", "Hopper-v4", "Humanoid-v4", "InvertedPendulum-v4", "Pusher-v4", "Walker2d-v4"),
}
# The sweep's default γ values are the paper's.
PAPER_GAMMAS = DEFAULT_GAMMAS
# The paper's variants in its order, as the training flags that make them: PPO (γ_train = 1), PGG (γ_train =
# 1.1) and PGG with conditioning dropout 0.1. A variant's id is never written here: it is the one
# pgg_utils.identity.variant_id gives a run of its flags (reproduce.grid_variants).
VARIANTS = (
    ("--guidance", "1.0", "--cond-dropout", "0.0"),
    ("--guidance", "1.1", "--cond-dropout", "0.0"),
    ("--guidance", "1.0", "--cond-dropout", "0.1"),
)
# Variants beyond the paper, the future work it names (scheduled and adaptive γ_train, guidance on a
# goal), as the training flags that make them; "{goal}" stands for the task's GOAL_DIMS.
BEYOND_VARIANTS = (
    # linear from 1 to 1.2: the same mean γ_train as the paper's constant 1.1, with no guidance while
    # the null branch has learned nothing
    ("--guidance", "1", "--guidance-schedule", "linear", "--guidance-final", "1.2"),
    # held at the KL that the constant 1.1 reaches over its first 300k Hopper steps (a pilot, README of
    # results/beyond), within γ_train 1 to 1.3
    ("--guidance", "1.1", "--guidance-schedule", "adaptive", "--guidance-kl-target", "0.04",
     "--guidance-bounds", "1", "1.3"),
    ("--guidance", "1.1", "--null-dims", "{goal}"),
    # the unconditional branch clones the rollout's actions, the null embedding alone (results/beyond/bc_train's pilot)
    ("--guidance", "1.1", "--null-bc-coef", "0.1"),
    # the null on the command of paper_study/cheetah_velocity/ (its COMMAND_INDEX, 17): π(a|s, ∅) cannot read the
    # command, but trained without dropout it is the policy at one learned pseudo-command, not a command-agnostic
    # one (results/beyond/command)
    ("--guidance", "1.1", "--null-dims", "17"),
    # classifier-free guidance's recipe on a condition: the goal or the command dropped with probability 0.1 in
    # updates, both branches trained at γ_train 1, guidance only at test (results/beyond/condition_dropout)
    ("--guidance", "1", "--null-dims", "{goal}", "--cond-dropout", "0.1"),
    ("--guidance", "1", "--null-dims", "17", "--cond-dropout", "0.1"),
)  # fmt: skip
# The ids of VARIANTS in the paper's order, for the readers that sort by it without importing a training
# script (torch); tests/test_reproduce.py checks that they are the ids reproduce derives.
PAPER_ORDER = ("ppo", "pgg_g1.1", "pgg_drop0.1")


# Our variant -> the paper's (method, training guidance) in paper_study/data/paper_results.csv: the rows of the
# paper's tables a run of that variant is compared with. Any other variant is compared with none.
PAPER_ROWS_OF_VARIANT = {"ppo": ("ppo", ""), "pgg_g1.1": ("pgg", "1.1")}


def paper_rows(variant: str) -> tuple[str, str] | None:
    """(method, training guidance) of the paper's table rows a variant is compared with, or None."""
    return PAPER_ROWS_OF_VARIANT.get(variant)


# The fields of a configuration label (identity.Configuration.label_fields) that name the software stack a
# run trained on, not how it trained: a cell from another MuJoCo is the paper's configuration, marked †.
STACK_FIELDS = ("mujoco", "versions")


def is_paper_configuration(row: dict) -> bool:
    """Whether a summary row's configuration is one the paper's tables hold: a variant they have rows of,
    trained by the repository's own script with no training argument other than the paper's (its label's
    fields name at most the stack). A fork (`script`), a fitted null (`null`) or any other argument
    (`learning_rate`, `total_timesteps`, a fork's own) is another configuration."""
    return paper_rows(row["variant"]) is not None and set(config_fields(row)) <= set(STACK_FIELDS)


def variant_flags(flags: tuple[str, ...], env_id: str) -> list[str]:
    """A variant's training flags (VARIANTS, BEYOND_VARIANTS) on `env_id`, "{goal}" replaced by the task's
    GOAL_DIMS; ValueError (`needs goal dimensions; ...`) where the task has none."""
    if "{goal}" in flags and env_id not in GOAL_DIMS:
        raise ValueError(f"needs goal dimensions; only {', '.join(GOAL_DIMS)} have them")
    return [part for flag in flags for part in ([str(d) for d in GOAL_DIMS[env_id]] if flag == "{goal}" else [flag])]


PAPER_SEEDS = 5  # the paper's "mean ± 95% CI" is over 5 seeds (see the README's "The statistic")


def paper_name(variant: str) -> str:
    """The paper's name of a variant (ppo -> PPO, pgg_g1.1 -> PGG, γ_train = 1.1, pgg_drop0.1 -> PGG,
    dropout 0.1), and a name in its words for the others (pgg_g1to1.2 -> PGG, γ_train 1 → 1.2;
    pgg_adaptive1.1_kl0.04 -> PGG, adaptive γ_train from 1.1, KL target 0.04; ..._goal -> ..., goal null)."""
    if variant == "ppo":
        return "PPO"
    if not variant.startswith("pgg_"):
        return variant
    parts = []
    for part in variant[4:].split("_"):
        if part.startswith("g") and "to" in part:
            parts.append("γ_train {} → {}".format(*part[1:].split("to")))
        elif part.startswith("g") and part != "goal":
            parts.append(f"γ_train = {part[1:]}")
        elif part.startswith("adaptive"):
            parts.append(f"adaptive γ_train from {part[8:]}")
        elif part.startswith("kl"):
            parts.append(f"KL target {part[2:]}")
        elif part.startswith("drop"):
            parts.append(f"dropout {part[4:]}")
        elif part.startswith("bc"):
            routed = part.endswith("actor")
            parts.append(f"behaviour-cloned null {part[2:].removesuffix('actor')}{' (actor too)' if routed else ''}")
        elif part == "goal":
            parts.append("goal null")
        elif part.startswith("null"):
            parts.append(f"null on dims {part[4:]}")
        else:
            parts.append(part)
    return "PGG, " + ", ".join(parts)


@functools.cache
def action_kind(env_id: str) -> str:
    """`discrete` or `continuous`: the one rule for which script trains a task and which table it
    belongs to, by the action space of the task itself. ValueError for an unknown id."""
    import gymnasium as gym

    if env_id in PAPER_ENVS["discrete"]:
        return "discrete"
    if env_id in PAPER_ENVS["continuous"]:
        return "continuous"
    try:
        env = gym.make(env_id)
    except Exception as e:  # unknown ids, missing dependencies: whatever the env's import raises
        raise ValueError(
            f"cannot make environment {env_id!r}: {str(e).splitlines()[0] if str(e) else type(e).__name__}"
        ) from None
    space = env.action_space
    env.close()
    if isinstance(space, gym.spaces.Discrete):
        return "discrete"
    if isinstance(space, gym.spaces.Box):
        return "continuous"
    raise ValueError(f"{env_id} has a {type(space).__name__} action space; the scripts train Discrete or Box")


def variant_rank(variant: str) -> int:
    """A variant's place in the paper's order (PAPER_ORDER), any other after them: how tables and legends sort."""
    return PAPER_ORDER.index(variant) if variant in PAPER_ORDER else len(PAPER_ORDER)


def with_series(name: str, series: str) -> str:
    """A name with the label of its configuration, where an env and variant hold several: `name [series]`."""
    return name + (f" [{series}]" if series else "")


def series_name(variant: str, series: str) -> str:
    """The paper's name of a variant, with its configuration label where one env and variant hold several."""
    return with_series(paper_name(variant), series)
