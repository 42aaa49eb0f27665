"""A checkpoint's contract with its task: the observation and action spaces it was trained on, those of the env its
script's `make_env` makes.

Training records `describe(...)` in every checkpoint (key `task_spaces`); whatever evaluates the checkpoint
compares it with the task it is handed (`mismatch`), so a task whose spaces changed since training is named in
one line instead of being evaluated with plausible, wrong numbers. Checkpoints saved before the contract was
recorded are checked on the sizes they hold (obs_dim, and n_actions or action_dim)."""

import gymnasium as gym
import numpy as np


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
