"""The paper's experiment, written down once: its tasks, variants, swept γ values, and the training
defaults that name a configuration. Plain data and a few rules; no torch."""

import functools

PAPER_ENVS = {
    "discrete": ("Acrobot-v1", "CartPole-v1"),
    "continuous": ("HalfCheetah-v4", "Hopper-v4", "Humanoid-v4", "InvertedPendulum-v4", "Pusher-v4", "Walker2d-v4"),
}
PAPER_GAMMAS = {
    "discrete": (1.0, 1.5, 2.0, 5.0, 10.0, 20.0),
    "continuous": (1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.5),
}
# Variant id -> (training guidance γ_train, conditioning dropout), in the paper's order.
VARIANTS = {"ppo": (1.0, 0.0), "pgg_g1.1": (1.1, 0.0), "pgg_drop0.1": (1.0, 0.1)}
# The observation dimensions a goal-conditioned null embedding replaces (--null-dims), from gymnasium's
# documentation of the v4 observations: Reacher's target position (4, 5) and fingertip-minus-target
# vector (8, 9, 10); Pusher's goal position (20, 21, 22). Reacher draws its target anew each episode;
# Pusher's goal is the same in every episode (gymnasium's PusherEnv), so its goal null is a control.
GOAL_DIMS = {"Reacher-v4": (4, 5, 8, 9, 10), "Pusher-v4": (20, 21, 22)}
# Variants beyond the paper, the future work it names (scheduled and adaptive γ_train, guidance on a
# goal), as the training flags that make them; "{goal}" stands for the task's GOAL_DIMS. Each id is the
# one pgg_utils.identity gives a run of those flags (tests/test_extending.py).
BEYOND_VARIANTS = {
    # linear from 1 to 1.2: the same mean γ_train as the paper's constant 1.1, with no guidance while
    # the null branch has learned nothing
    "pgg_g1to1.2": ("--guidance", "1", "--guidance-schedule", "linear", "--guidance-final", "1.2"),
    # held at the KL that the constant 1.1 reaches over its first 300k Hopper steps (a pilot, README of
    # results/beyond), within γ_train 1 to 1.3
    "pgg_adaptive1.1_kl0.04": ("--guidance", "1.1", "--guidance-schedule", "adaptive", "--guidance-kl-target", "0.04",
                               "--guidance-bounds", "1", "1.3"),
    "pgg_g1.1_goal": ("--guidance", "1.1", "--null-dims", "{goal}"),
}  # fmt: skip


# Our variant -> the paper's (method, training guidance) in data/paper_results.csv: the rows of the
# paper's tables a run of that variant is compared with. Any other variant is compared with none.
PAPER_ROWS_OF_VARIANT = {"ppo": ("ppo", ""), "pgg_g1.1": ("pgg", "1.1")}


def paper_rows(variant: str) -> tuple[str, str] | None:
    """(method, training guidance) of the paper's table rows a variant is compared with, or None."""
    return PAPER_ROWS_OF_VARIANT.get(variant)


def variant_flags(variant: str, env_id: str) -> list[str]:
    """The training flags of a variant of the paper (VARIANTS) or beyond it (BEYOND_VARIANTS) on `env_id`;
    ValueError where the variant needs goal dimensions the task has none of."""
    if variant in VARIANTS:
        guidance, dropout = VARIANTS[variant]
        return ["--guidance", str(guidance), "--cond-dropout", str(dropout)]
    flags = []
    for flag in BEYOND_VARIANTS[variant]:
        if flag == "{goal}":
            if env_id not in GOAL_DIMS:
                raise ValueError(f"{variant} needs goal dimensions; only {', '.join(GOAL_DIMS)} have them")
            flags += [str(d) for d in GOAL_DIMS[env_id]]
        else:
            flags.append(flag)
    return flags


PAPER_SEEDS = 5  # the paper's "mean ± 95% CI" is over 5 seeds (see the README's "The statistic")

# PGG's arguments at the values that train PPO (a constant γ_train of 1, the whole observation nulled).
PGG_REFERENCE = {"guidance": 1.0, "guidance_schedule": "constant", "guidance_final": None, "guidance_kl_target": None,
                 "guidance_bounds": (1.0, 1.5), "cond_dropout": 0.0}  # fmt: skip
# The training arguments a configuration is named against (config_label): CleanRL's defaults for
# ppo.py and ppo_continuous_action.py (its `gamma` is our `discount`), with our PGG arguments at PPO.
# Frozen here, as data: changing a script's default neither renames nor splits an old experiment.
# An argument added later belongs here at the value that trains as before it existed.
REFERENCE_ARGS = {
    "discrete": {
        "total_timesteps": 500_000, "learning_rate": 2.5e-4, "num_envs": 4, "num_steps": 128, "anneal_lr": True,
        "discount": 0.99, "gae_lambda": 0.95, "num_minibatches": 4, "update_epochs": 4, "norm_adv": True,
        "clip_coef": 0.2, "clip_vloss": True, "ent_coef": 0.01, "vf_coef": 0.5, "max_grad_norm": 0.5,
        "target_kl": None, **PGG_REFERENCE,
    },
    "continuous": {
        "total_timesteps": 1_000_000, "learning_rate": 3e-4, "num_envs": 1, "num_steps": 2048, "anneal_lr": True,
        "discount": 0.99, "gae_lambda": 0.95, "num_minibatches": 32, "update_epochs": 10, "norm_adv": True,
        "clip_coef": 0.2, "clip_vloss": True, "ent_coef": 0.0, "vf_coef": 0.5, "max_grad_norm": 0.5,
        "target_kl": None, "obs_clip": 10.0, "reward_clip": 10.0, **PGG_REFERENCE, "null_dims": None,
    },
}  # fmt: skip


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


@functools.cache
def is_mujoco(env_id: str) -> bool:
    """Whether the task runs on MuJoCo (its results then depend on the MuJoCo version)."""
    import gymnasium as gym

    try:
        entry_point = gym.spec(env_id).entry_point
    except gym.error.Error:
        return False
    return isinstance(entry_point, str) and entry_point.startswith("gymnasium.envs.mujoco")


def variant_rank(variant: str) -> int:
    """A variant's place in the paper's order (VARIANTS), any other after them: how tables and legends sort."""
    return list(VARIANTS).index(variant) if variant in VARIANTS else len(VARIANTS)


def series_name(variant: str, series: str) -> str:
    """The paper's name of a variant, with its configuration label where one env and variant hold several."""
    return paper_name(variant) + (f" [{series}]" if series else "")
