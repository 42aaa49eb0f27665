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
PAPER_SEEDS = 5  # the paper's "mean ± 95% CI" is over 5 seeds (see the README's "The statistic")

# The training arguments a configuration is named against (config_label): CleanRL's defaults for
# ppo.py and ppo_continuous_action.py (its `gamma` is our `discount`), with our PGG arguments at PPO.
# Frozen here, as data: changing a script's default neither renames nor splits an old experiment.
# An argument added later belongs here at the value that trains as before it existed.
REFERENCE_ARGS = {
    "discrete": {
        "total_timesteps": 500_000, "learning_rate": 2.5e-4, "num_envs": 4, "num_steps": 128, "anneal_lr": True,
        "discount": 0.99, "gae_lambda": 0.95, "num_minibatches": 4, "update_epochs": 4, "norm_adv": True,
        "clip_coef": 0.2, "clip_vloss": True, "ent_coef": 0.01, "vf_coef": 0.5, "max_grad_norm": 0.5,
        "target_kl": None, "guidance": 1.0, "cond_dropout": 0.0,
    },
    "continuous": {
        "total_timesteps": 1_000_000, "learning_rate": 3e-4, "num_envs": 1, "num_steps": 2048, "anneal_lr": True,
        "discount": 0.99, "gae_lambda": 0.95, "num_minibatches": 32, "update_epochs": 10, "norm_adv": True,
        "clip_coef": 0.2, "clip_vloss": True, "ent_coef": 0.0, "vf_coef": 0.5, "max_grad_norm": 0.5,
        "target_kl": None, "obs_clip": 10.0, "reward_clip": 10.0, "guidance": 1.0, "cond_dropout": 0.0,
    },
}  # fmt: skip


def variant_id(train_guidance: float, cond_dropout: float) -> str:
    """`ppo`, `pgg_g1.1`, `pgg_drop0.1`, `pgg_g1.1_drop0.1`: a run's variant from its two PGG arguments."""
    train_guidance, cond_dropout = float(train_guidance), float(cond_dropout)
    if cond_dropout == 0:
        return "ppo" if train_guidance == 1.0 else f"pgg_g{train_guidance:g}"
    return f"pgg_drop{cond_dropout:g}" if train_guidance == 1.0 else f"pgg_g{train_guidance:g}_drop{cond_dropout:g}"


def paper_name(variant: str) -> str:
    """The paper's name of a variant: ppo -> PPO, pgg_g1.1 -> PGG, γ_train = 1.1, pgg_drop0.1 -> PGG, dropout 0.1."""
    if variant == "ppo":
        return "PPO"
    if not variant.startswith("pgg_"):
        return variant
    parts = []
    for part in variant[4:].split("_"):
        if part.startswith("g"):
            parts.append(f"γ_train = {part[1:]}")
        elif part.startswith("drop"):
            parts.append(f"dropout {part[4:]}")
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
