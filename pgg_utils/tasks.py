"""The task as the training scripts and the sweep make it, written once: gym.make's env with its own returns recorded
directly on it (`task_env`, on which each script's `make_env` builds), the episodes a vector step ended
(`ended_episodes`), the training scripts' vector env (`make_vector_env`), what a vector env must be to train,
checkpoint, resume and be swept (`vector_env_error`), and the task's shapes a checkpoint records (`trained_task`). A checkpoint's contract with its task is here too: the observation and action spaces it was trained on (`describe`, recorded in every checkpoint as `task_spaces`), compared with those of the env its script's make_env makes (`mismatch`), so a task whose spaces changed since training is named in one line, not evaluated with plausible, wrong numbers."""

import gymnasium as gym
import numpy as np

# The info key under which task_env reports an episode's return and length. Not RecordEpisodeStatistics' default,
# "episode", so that a recorder a fork adds above it (CleanRL's make_env has one) neither collides with it nor is
# taken for it.
TASK_EPISODE = "task_episode"


def task_env(env_id: str, video_dir=None, render_mode: str | None = None, below_record=()) -> gym.Env:
    """gym.make's env of `env_id` with RecordEpisodeStatistics directly on it: every reported return (training's
    charts/episodic_return, the sweep's) is the sum of the task's own rewards, whatever make_env wraps around this
    env (a reward scale, a bonus: they shape what the agent trains on, never what is reported). `below_record`:
    wrappers (env -> env) put under the recorder, in order, the one place where a fork says it reports a shaped
    return (a reward wrapper there is summed into every reported return); the continuous script's
    FlattenObservation, which changes no reward, sits there. With `video_dir`, RecordVideo records there;
    `render_mode` is gym.make's."""
    render = "rgb_array" if video_dir is not None else render_mode
    env = gym.make(env_id, **({"render_mode": render} if render else {}))  # a task may take no render_mode
    if video_dir is not None:
        env = gym.wrappers.RecordVideo(env, str(video_dir), disable_logger=True)
    for wrapper in below_record:
        env = wrapper(env)
    return gym.wrappers.RecordEpisodeStatistics(env, stats_key=TASK_EPISODE)


def records_task_return(env: gym.Env) -> bool:
    """Whether task_env's recorder is in `env`'s wrapper chain."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.RecordEpisodeStatistics) and vars(env).get("_stats_key") == TASK_EPISODE:
            return True
        env = env.env
    return False


def ended_episodes(infos: dict) -> list[tuple[float, int]]:
    """(return, length) of each episode that one step of a same-step autoreset vector env ended, in sub-env order:
    the task's own, as task_env records them."""
    if "final_info" not in infos:
        return []
    ended = infos["final_info"]
    episodes = ended[TASK_EPISODE]
    return [(float(episodes["r"][i]), int(episodes["l"][i])) for i in np.flatnonzero(ended[f"_{TASK_EPISODE}"])]


def make_vector_env(make_env, env_id: str, num_envs: int, seed: int, video_dir=None, wrap=None) -> gym.vector.VectorEnv:
    """A training script's vector env: `num_envs` sub-envs of `make_env`'s task, each wrapped by `wrap` (env -> env:
    what training alone adds, the continuous script's action clipping and reward normalisation), in one process
    (checkpoints hold every sub-env's state), resetting a finished sub-env within the same step (the gym 0.29
    convention GAE relies on). With `video_dir`, the first sub-env's episodes are recorded there (CleanRL's schedule:
    episodes 0, 1, 8, 27, ...)."""
    wrap = wrap or (lambda env: env)
    envs = gym.vector.SyncVectorEnv(
        [lambda i=i: wrap(make_env(env_id, video_dir if i == 0 else None)()) for i in range(num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    envs.action_space.seed(seed)
    return envs


def vector_env_error(envs, task: gym.Env) -> str | None:
    """Why a training script cannot train on `envs`, what its make_vector_env returns, in one line that says what to
    do; None where it can. A checkpoint holds every sub-env's state, so that a run resumes exactly: only a
    gym.vector.SyncVectorEnv, unwrapped, exposes them. GAE here reads the next episode's first observation in the
    step that ends one (same-step autoreset). Each sub-env reports the task's own return (task_env). And the sub-envs
    act in the task that `make_env` makes (`task`): the one the checkpoints record and the sweep evaluates."""
    name = type(envs).__name__
    if isinstance(envs, gym.vector.VectorWrapper):
        return (f"make_vector_env returns its vector env wrapped in {name}: a checkpoint holds the sub-envs' state, "
                "not a vector wrapper's, so a resumed run would not continue it; wrap each sub-env instead, in "
                "make_env (the task's own return is recorded there already)")  # fmt: skip
    if not isinstance(envs, gym.vector.SyncVectorEnv):
        return (f"make_vector_env returns {name}: a checkpoint holds each sub-env's state so that a run resumes "
                "exactly, which only gym.vector.SyncVectorEnv (one process) exposes; use SyncVectorEnv")  # fmt: skip
    if (mode := envs.metadata.get("autoreset_mode")) != gym.vector.AutoresetMode.SAME_STEP:
        return (f"make_vector_env's SyncVectorEnv resets a finished sub-env with autoreset mode {mode}; GAE here "
                "needs the next episode's first observation in the step that ends one: pass "
                "autoreset_mode=gym.vector.AutoresetMode.SAME_STEP")  # fmt: skip
    if not all(records_task_return(env) for env in envs.envs):
        return ("make_vector_env's sub-envs do not report the task's own return: make each with make_env, and "
                "make_env's env with pgg_utils.tasks.task_env, which records it on gym.make's env")  # fmt: skip
    if error := vector_mismatch(task, envs.single_observation_space, envs.single_action_space):
        return (f"make_vector_env's sub-envs act in another task than make_env makes ({error}): the checkpoints "
                "record make_env's, which the sweep evaluates; put the wrapper in make_env")  # fmt: skip
    return None


def trained_task(script, env_id: str, envs) -> tuple[dict | None, str | None]:
    """(the shapes a checkpoint records, checkpoint_shapes of the env `script.make_env` makes, as the sweep
    makes it; None, the one line that refuses training): a vector env that cannot train, checkpoint, resume and be
    swept, or observations the scripts' networks cannot take, is refused before the shapes are read."""
    task = script.make_env(env_id)()
    try:
        error = vector_env_error(envs, task) or observation_shape_error(env_id, envs.single_observation_space)
        return (None, error) if error else (checkpoint_shapes(task), None)
    finally:
        task.close()


def checkpoint_shapes(task: gym.Env) -> dict:
    """What a checkpoint records of the spaces of `task`, the env a script's make_env makes: the sizes its
    make_agent reads (a Box action's own bounds: the training envs' ClipAction has ±inf ones), and `task_spaces`,
    the contract whatever evaluates the checkpoint compares with its task."""
    obs_space, action_space = task.observation_space, task.action_space
    if isinstance(action_space, gym.spaces.Discrete):
        sizes = {"obs_dim": int(obs_space.shape[0]), "n_actions": int(action_space.n)}
    else:
        sizes = {"obs_dim": int(obs_space.shape[0]), "action_dim": int(action_space.shape[0]),
                 "action_low": action_space.low.tolist(), "action_high": action_space.high.tolist()}  # fmt: skip
    return {**sizes, "task_spaces": describe(obs_space, action_space)}


def describe(observation_space: gym.Space, action_space: gym.Space) -> dict:
    """The spaces as plain data: the observation's shape; a Discrete action's n and start, a Box action's shape
    and bounds."""
    if isinstance(action_space, gym.spaces.Discrete):
        action = {"type": "Discrete", "n": int(action_space.n), "start": int(action_space.start)}
    elif isinstance(action_space, gym.spaces.Box):
        action = {
            "type": "Box",
            "shape": list(action_space.shape),
            "low": np.asarray(action_space.low, np.float64).ravel().tolist(),
            "high": np.asarray(action_space.high, np.float64).ravel().tolist(),
        }
    else:
        action = {"type": type(action_space).__name__}
    return {"observation": {"shape": list(observation_space.shape or ())}, "action": action}


def recorded(ckpt: dict) -> dict:
    """The checkpoint's contract, from `task_spaces` or, for an older checkpoint, from the sizes it holds
    (fields it does not know are left out, so they are not compared)."""
    if "task_spaces" in ckpt:
        return ckpt["task_spaces"]
    action = {"type": "Discrete", "n": ckpt["n_actions"]} if "n_actions" in ckpt else {"type": "Box"}
    if "action_dim" in ckpt:
        action["shape"] = [ckpt["action_dim"]]
    return {"observation": {"shape": [ckpt["obs_dim"]]} if "obs_dim" in ckpt else {}, "action": action}


def mismatch(contract: dict, observation_space: gym.Space, action_space: gym.Space) -> str | None:
    """One line naming how the task's spaces differ from those a checkpoint was trained on, or None."""
    now = describe(observation_space, action_space)
    then_obs, then_act = contract.get("observation", {}), contract.get("action", {})
    if "shape" in then_obs and list(then_obs["shape"]) != now["observation"]["shape"]:
        return f"observation shape {tuple(then_obs['shape'])} in training, {tuple(now['observation']['shape'])} now"
    if then_act.get("type") != now["action"]["type"]:
        return f"action space {then_act.get('type')} in training, {now['action']['type']} now"
    for field in ("n", "start", "shape", "low", "high"):
        if field in then_act and list(np.atleast_1d(then_act[field])) != list(np.atleast_1d(now["action"][field])):
            return f"action {field} {then_act[field]} in training, {now['action'][field]} now"
    return None


def vector_mismatch(task: gym.Env, observation_space: gym.Space, action_space: gym.Space) -> str | None:
    """One line naming how the single spaces of a training script's vector env differ from those of `task`, the env
    its make_env makes, or None. Infinite bounds on every dimension are ClipAction's (the continuous script puts it
    on each sub-env), which clips to the bounds of the env it wraps: only the shape is compared then."""
    contract = describe(task.observation_space, task.action_space)
    clipped = isinstance(action_space, gym.spaces.Box) and np.isinf([action_space.low, action_space.high]).all()
    if clipped:
        contract["action"] = {key: value for key, value in contract["action"].items() if key not in ("low", "high")}
    return mismatch(contract, observation_space, action_space)


def observation_shape_error(env_id: str, observation_space: gym.Space) -> str | None:
    """What training says of observations the scripts' networks cannot take (they read a vector, a 1-D Box: a frame
    stack of vectors is (k, n)), or None."""
    shape = getattr(observation_space, "shape", None)
    if shape is not None and len(shape) == 1:
        return None
    return (f"{env_id}'s observations have shape {shape} as make_env makes them; this script's networks take a vector "
            "(a 1-D Box): flatten them in make_env (gymnasium.wrappers.FlattenObservation, after a frame stack)")  # fmt: skip
