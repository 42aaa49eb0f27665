"""The task as the training scripts and the sweep make it, written once: gym.make's env with its own returns recorded
directly on it (`task_env`, on which each script's `make_env` builds), the episodes a vector step ended
(`ended_episodes`), the training scripts' vector env (`make_vector_env`), what a vector env must be to train,
checkpoint, resume and be swept (`vector_env_error`), and the task's shapes a checkpoint records (`trained_task`)."""

import gymnasium as gym
import numpy as np

from pgg_utils import spaces

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
    if error := spaces.vector_mismatch(task, envs.single_observation_space, envs.single_action_space):
        return (f"make_vector_env's sub-envs act in another task than make_env makes ({error}): the checkpoints "
                "record make_env's, which the sweep evaluates; put the wrapper in make_env")  # fmt: skip
    return None


def trained_task(script, env_id: str, envs) -> tuple[dict | None, str | None]:
    """(the shapes a checkpoint records, spaces.checkpoint_shapes of the env `script.make_env` makes, as the sweep
    makes it; None, the one line that refuses training): a vector env that cannot train, checkpoint, resume and be
    swept, or observations the scripts' networks cannot take, is refused before the shapes are read."""
    task = script.make_env(env_id)()
    try:
        error = vector_env_error(envs, task) or spaces.observation_shape_error(env_id, envs.single_observation_space)
        return (None, error) if error else (spaces.checkpoint_shapes(task), None)
    finally:
        task.close()
