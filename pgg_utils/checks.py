"""The checks a training run passes before the disk is touched: its arguments, and whether its
script can train its env here (action space, observations, rendering)."""

import importlib.util
import inspect
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import gymnasium as gym

from pgg_utils.arguments import ARGUMENT_RULES, run_name_error
from pgg_utils.guidance import schedule_error
from pgg_utils.identity import Configuration
from pgg_utils.scripts import ORIGINALS, REPOSITORY

# Ids that a module registers when it is imported, by their start: gym.make finds them with the module named
# first (`module:id`), and what installs it. dm-control 1.0.14, the release for MuJoCo 2.3.7, fails on numpy 2.
REGISTERED_ON_IMPORT = {
    "dm_control/": ("shimmy", "pip install 'shimmy[dm-control]'"),
    "MiniGrid-": ("minigrid", "pip install minigrid"),
    "BabyAI-": ("minigrid", "pip install minigrid"),
    "ALE/": ("ale_py", "pip install ale-py"),
}
DM_CONTROL_NUMPY = (
    "dm-control 1.0.14, the release for MuJoCo 2.3.7, fails on numpy 2: use an environment with numpy<2 "
    "(docs/usage.md, Train)"
)


def make_hint(env_id: str, error: Exception) -> str:
    """What to add to gym.make's error for `env_id`: the module to name before an id that a module registers (an
    unknown name or namespace otherwise), and for dm_control's tasks the numpy limit; "" where there is nothing."""
    task = env_id.split(":", 1)[-1]
    hints = []
    if isinstance(error, (gym.error.NamespaceNotFound, gym.error.NameNotFound)) and ":" not in env_id:
        module, install = next((m for start, m in REGISTERED_ON_IMPORT.items() if task.startswith(start)), (None, None))
        hints.append(f"{module} registers it when imported: --env-id {module}:{task} ({install})" if module else
                     "a task that a module registers needs the module named first, --env-id module:Id "
                     "(shimmy:dm_control/..., minigrid:MiniGrid-...)")  # fmt: skip
    if task.startswith("dm_control/"):
        hints.append(DM_CONTROL_NUMPY)
    return "".join(f"; {hint}" for hint in hints)


def argument_error(args, kind: str, script: str | Path | None = None, make_env=None) -> str | None:
    """A one-line description of what is wrong with the `args` of training script `script` (None: the
    repository's own for `kind`, discrete or continuous, the action space it trains), or None. Makes the
    env once, with the script's `make_env` (None: gym.make); touches no file."""
    for name, (holds, requirement) in ARGUMENT_RULES.items():
        if hasattr(args, name) and not holds(getattr(args, name)):
            return f"--{name.replace('_', '-')} must be {requirement}, got {getattr(args, name)!r}"
    if error := schedule_error(args) or run_name_error(args.run_name):
        return error
    if args.run_name is None and (
        error := run_name_error(
            Configuration.of_run(script or REPOSITORY / f"{ORIGINALS[kind]}.py", kind, args).run_name,
            "the run name built from --env-id and --exp-name",
        )
    ):
        return f"{error}: choose another --exp-name, or pass --run-name"
    batch_size = args.num_envs * args.num_steps
    if args.num_minibatches <= 0 or batch_size % args.num_minibatches:
        return f"--num-minibatches must divide num_envs * num_steps = {batch_size}"
    if args.norm_adv and batch_size // args.num_minibatches < 2:
        return (f"minibatches of {batch_size // args.num_minibatches} row cannot normalise advantages (a zero std): "
                "use fewer --num-minibatches, more --num-steps, or --no-norm-adv")  # fmt: skip
    if args.checkpoint_interval < batch_size:
        return f"--checkpoint-interval must be at least one batch, num_envs * num_steps = {batch_size}"
    if args.resume and args.overwrite:
        return "--resume and --overwrite exclude each other"
    if args.compile and not any(shutil.which(cxx) for cxx in (os.environ.get("CXX", "g++"), "g++", "clang++")):
        return "--compile needs a C++ compiler (g++ or clang++ on PATH, or $CXX)"
    if args.track and importlib.util.find_spec("wandb") is None:
        return "--track needs Weights and Biases: pip install wandb"
    return env_error(args.env_id, kind, args.capture_video, getattr(args, "null_dims", None), make_env)


def made_env(env_id: str, make_env=None, render_mode: str | None = None) -> gym.Env:
    """The env of `env_id` as a training script's `make_env` makes it (None: gym.make's), rendering with
    `render_mode`; a make_env that takes no render_mode (written before it did) renders gym.make's env."""
    if make_env is None or (render_mode and "render_mode" not in inspect.signature(make_env).parameters):
        return gym.make(env_id, render_mode=render_mode)
    return make_env(env_id, render_mode=render_mode)() if render_mode else make_env(env_id)()


def env_error(env_id: str, kind: str, capture_video: bool = False, null_dims=None, make_env=None) -> str | None:
    """Why a training script of `kind` cannot train `env_id` here (with the null embedding on `null_dims`), or None:
    the env as its `make_env` makes it (None: gym.make's), whose spaces the agent acts in."""
    try:
        env = made_env(env_id, make_env, "rgb_array" if capture_video else None)
    except ImportError as e:
        if env_id == "Pusher-v4":
            return "Pusher-v4 needs mujoco<3 (pip install mujoco==2.3.7, Python <= 3.11); with a newer mujoco use Pusher-v5"
        return f"cannot make environment {env_id!r}: {e}{make_hint(env_id, e)}"
    except Exception as e:  # unknown ids, missing dependencies, a bad MUJOCO_GL: whatever the env's import raises
        backend = os.environ.get("MUJOCO_GL")
        hint = (f" (MUJOCO_GL={backend}: is its library installed? osmesa needs apt-get install libosmesa6, egl "
                "libegl1)" if backend and capture_video else "")  # fmt: skip
        return f"cannot make environment {env_id!r}: {e}{hint}{make_hint(env_id, e)}"
    action_space, observation_space = env.action_space, env.observation_space
    error = video_error(env) if capture_video else None
    env.close()
    wanted, other = (gym.spaces.Discrete, "continuous") if kind == "discrete" else (gym.spaces.Box, "discrete")
    if not isinstance(action_space, (gym.spaces.Discrete, gym.spaces.Box)):
        return (f"{env_id} has a {type(action_space).__name__} action space; neither script trains it "
                "(ppo_pgg_discrete.py: Discrete, ppo_pgg_continuous.py: Box)")  # fmt: skip
    if not isinstance(action_space, wanted):
        return (f"{env_id} has a {type(action_space).__name__} action space; this script needs "
                f"{wanted.__name__} (use ppo_pgg_{other}.py)")  # fmt: skip
    if kind == "discrete" and not (isinstance(observation_space, gym.spaces.Box) and len(observation_space.shape) == 1):
        return f"{env_id} has a {type(observation_space).__name__} observation space; ppo_pgg_discrete.py needs a vector (1-D Box)"
    obs_dim = gym.spaces.flatdim(observation_space)
    if obs_dim == 0:
        return f"{env_id} has an empty observation space (shape {observation_space.shape}): there is no state to condition on"
    if null_dims is not None and not all(0 <= d < obs_dim for d in null_dims):
        return f"--null-dims must be observation indices of {env_id}, 0..{obs_dim - 1}, got {list(null_dims)}"
    return error


def video_error(env: gym.Env) -> str | None:
    """Why this env cannot be recorded here (a missing package or rendering backend), or None."""
    if not os.environ.get("XDG_RUNTIME_DIR"):  # SDL (pygame's renderer) complains of it at every init
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="xdg_runtime_")
    try:
        import moviepy  # noqa: F401  (gymnasium's RecordVideo writes with it)

        env.reset(seed=0)
        with warnings.catch_warnings():  # a failing GL backend warns before it raises
            warnings.simplefilter("ignore")
            if env.render() is None:
                return f"{env.spec.id} renders no frames"
    except ImportError as e:
        return f"--capture-video needs the [video] extra (pip install -e '.[video]'): {e}"
    except Exception as e:  # rendering backends fail with anything from OpenGL, pygame or MuJoCo
        hint = (
            "; headless MuJoCo needs MUJOCO_GL=egl or osmesa (apt-get install libosmesa6)"
            if "mujoco" in type(env.unwrapped).__module__
            else ""
        )
        return f"--capture-video cannot render {env.spec.id} here ({type(e).__name__}: {e}){hint}"
    return None
