"""What a checkpoint holds to continue a run exactly: every RNG's state, the sub-envs' state
mid-episode (wrapper counters, a classic-control or MuJoCo task's own state) and the optimizer's,
pickle-free."""

import random

import gymnasium as gym
import numpy as np
import torch


def seed_everything(args) -> None:
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    torch.use_deterministic_algorithms(args.torch_deterministic)
    torch.set_num_threads(args.torch_threads)


def rng_state() -> dict:
    """torch's, numpy's and Python's global generators, pickle-free."""
    numpy_state = np.random.get_state(legacy=False)
    numpy_state["state"]["key"] = torch.from_numpy(numpy_state["state"]["key"].astype(np.int64))
    return {"torch": torch.get_rng_state(), "numpy": numpy_state, "python": random.getstate()}


def set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    numpy_state = state["numpy"]
    numpy_state["state"]["key"] = numpy_state["state"]["key"].numpy().astype(np.uint32)
    np.random.set_state(numpy_state)
    random.setstate(state["python"])


# What a sub-env carries from one step to the next, besides its RNG and a MuJoCo task's simulation
# state: wrapper counters (time limit, episode statistics, reward scaling) and a classic-control task's
# physical state. Saved with a checkpoint so that a resumed run continues the very episodes it was in.
ENV_STATE_ATTRIBUTES = (
    "_elapsed_steps", "_has_reset", "episode_returns", "episode_lengths", "state", "steps_beyond_terminated",
    "discounted_return", "return_mean", "return_var", "return_count",
)  # fmt: skip


def wrapper_chain(env: gym.Env):
    while True:
        yield env
        if not isinstance(env, gym.Wrapper):
            return
        env = env.env


def pickle_free(value):
    """`value` as a weights-only checkpoint holds it: arrays as tensors, numpy scalars as Python
    numbers, inside tuples and lists too (MountainCar's state is a tuple of np.float64)."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(value.copy())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, list)):
        return type(value)(pickle_free(v) for v in value)
    return value


def from_checkpoint(value):
    """The inverse of pickle_free: tensors back to (writable) numpy arrays."""
    if isinstance(value, torch.Tensor):
        return value.numpy().copy()
    if isinstance(value, (tuple, list)):
        return type(value)(from_checkpoint(v) for v in value)
    return value


def generator_state(rng) -> dict:
    """A task's RNG state, pickle-free: a Generator's bit generator state as it is, or a legacy RandomState's
    (dm_control's tasks through shimmy) under `random_state`, its key as int64."""
    if isinstance(rng, np.random.RandomState):
        state = rng.get_state(legacy=False)
        return {
            "random_state": {
                **state,
                "state": {**state["state"], "key": torch.from_numpy(state["state"]["key"].astype(np.int64))},
            }
        }
    return rng.bit_generator.state


def set_generator_state(rng, state: dict) -> None:
    """The inverse of generator_state, into `rng` in place."""
    if "random_state" in state:
        saved = state["random_state"]
        rng.set_state({**saved, "state": {**saved["state"], "key": saved["state"]["key"].numpy().astype(np.uint32)}})
    else:
        rng.bit_generator.state = state


def env_state(envs) -> list[dict]:
    """The state of every sub-env as plain values and tensors (pickle-free): its wrappers' counters and
    statistics, its RNG and, where it is a classic-control or MuJoCo task, the task's own state
    ("complete"; for other tasks a resumed run starts fresh episodes)."""
    states = []
    for env in envs.envs:
        task = env.unwrapped
        layers = [
            {name: pickle_free(value) for name, value in vars(layer).items() if name in ENV_STATE_ATTRIBUTES}
            for layer in wrapper_chain(env)
        ]
        kinds = [type(layer).__name__ for layer in wrapper_chain(env)]
        complete = type(task).__module__.startswith(("gymnasium.envs.classic_control", "gymnasium.envs.mujoco"))
        states.append(
            {"layers": layers, "layer_kinds": kinds, "rng": generator_state(task.np_random), "complete": complete}
        )
        if hasattr(task, "data"):
            # MuJoCo: every array of mjData, not only the integration state. Quantities derived from
            # the state (body positions, contact forces) lag it by one step after mj_step, and some
            # tasks read them (Humanoid's reward and observation): mj_forward would not restore them.
            data = task.data
            arrays = {name: getattr(data, name) for name in dir(data) if not name.startswith("_")}
            states[-1]["mujoco"] = {
                name: torch.from_numpy(a.copy()) for name, a in arrays.items() if isinstance(a, np.ndarray)
            }
            states[-1]["mujoco_time"] = float(data.time)
    return states


def matched_layers(chain: list, state: dict) -> list[tuple]:
    """(wrapper, its saved attributes) by the wrappers' kinds, in order: a run resumed with another
    --capture-video has a RecordVideo more or less in its chain. Checkpoints without the kinds match by
    position."""
    if "layer_kinds" not in state:
        return list(zip(chain, state["layers"]))
    saved = list(zip(state["layer_kinds"], state["layers"]))
    matched = []
    for layer in chain:
        position = next((i for i, (kind, _) in enumerate(saved) if kind == type(layer).__name__), None)
        if position is not None:
            matched.append((layer, saved[position][1]))
            saved = saved[position + 1 :]
    return matched


def restore_env_state(envs, states: list[dict]) -> None:
    for env, state in zip(envs.envs, states):
        for layer, saved in matched_layers(list(wrapper_chain(env)), state):
            for name, value in saved.items():
                setattr(layer, name, from_checkpoint(value))
        set_generator_state(env.unwrapped.np_random, state["rng"])
        if "mujoco" in state:
            data = env.unwrapped.data
            for name, saved in state["mujoco"].items():
                target = getattr(data, name)
                # Arrays sized by the contacts of the moment may differ in shape; the next step recomputes them.
                if target.flags.writeable and target.shape == tuple(saved.shape):
                    target[...] = saved.numpy()
            data.time = state["mujoco_time"]


def resume_state(iteration: int, optimizer, envs, next_obs: np.ndarray, next_done: np.ndarray, schedule) -> dict:
    """What continuing a run needs besides the model: the optimizer, the sub-envs mid-episode, the
    next observation, every RNG state and, for an adaptive γ_train, the schedule's state."""
    guidance = {"guidance": schedule.state_dict()} if schedule.kind == "adaptive" else {}
    return {
        **guidance,
        "iteration": iteration,
        "optimizer": optimizer.state_dict(),
        "envs": env_state(envs),
        "next_obs": torch.from_numpy(next_obs.copy()),
        "next_done": torch.from_numpy(next_done.copy()),
        "rng": rng_state(),
    }
