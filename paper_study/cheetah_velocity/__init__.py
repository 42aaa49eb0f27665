"""A command-conditioned task for "Beyond the paper": HalfCheetah told, each episode, how fast to run.

    python ppo_pgg_continuous.py --env-id paper_study.cheetah_velocity:HalfCheetahVelocity-v0 --null-dims 17

The meta-RL literature's velocity-conditioned HalfCheetah (Finn et al. 2017, "Model-Agnostic Meta-Learning",
section 5.3: a goal velocity drawn uniformly from [0, 2] for each task, the reward the negative absolute
difference between the cheetah's forward velocity and the goal, with a control cost), here as one task whose
command is part of what the agent sees: gymnasium's HalfCheetah-v4 (its physics, start states and control
cost, 0.1·Σa²), the commanded forward velocity v_cmd drawn uniformly from COMMAND_RANGE at every reset and
appended to the observation (index COMMAND_INDEX, the one `--null-dims` takes for a null on the command), and
the reward v_cmd − |v − v_cmd| − 0.1·Σa² = min(v, 2·v_cmd − v) − 0.1·Σa² in place of v − 0.1·Σa², with v
HalfCheetah-v4's own forward velocity (x displacement over the step's duration). That is Finn et al.'s
−|v − v_cmd| plus the episode's constant v_cmd, which changes no policy's ranking (every episode lasts its
1000 steps, as HalfCheetah-v4's, and the command is fixed within it), and it makes the reward HalfCheetah-v4's
own wherever v ≤ v_cmd: standing still earns 0 whatever the command, so the returns' spread does not grow with
the command, which PPO's reward scaling would divide every signal by (a pilot with −|v − v_cmd| alone had not
begun to run after 200k steps: results/beyond/command/pilot.txt).

`reset(options={"command": v})` sets the command instead of drawing it (an evaluation's commands inside and
outside the training range, beyond/command_tracking.py); the draw is made in either case, after the start
state's, so that one reset seed gives HalfCheetah-v4's start state for that seed and the same RNG state
whatever the command. Training imports nothing of this module: `gym.make` imports it by its id.
"""

import math

import gymnasium as gym
import numpy as np
from gymnasium.envs.mujoco.half_cheetah_v4 import HalfCheetahEnv

ENV_ID = "paper_study.cheetah_velocity:HalfCheetahVelocity-v0"
COMMAND_RANGE = (0.0, 2.0)  # m/s, the training commands (Finn et al. 2017's range)
COMMAND_INDEX = 17  # the command's place in the observation: after HalfCheetah-v4's 17 dimensions


class HalfCheetahVelocity(HalfCheetahEnv):
    """HalfCheetah-v4 with a commanded forward velocity in its observation and a reward for tracking it."""

    def __init__(self, command_range: tuple[float, float] = COMMAND_RANGE, **kwargs):
        low, high = (float(v) for v in command_range)
        if not (math.isfinite(low) and math.isfinite(high) and low <= high):
            raise ValueError(f"command_range must be two finite numbers, low <= high, got {command_range}")
        self.command_range = (low, high)
        self.command = low  # until the first reset; reset_model sets it before any observation is returned
        self._given_command = None
        super().__init__(**kwargs)  # HalfCheetah-v4's defaults (render_mode and the rest pass through)
        gym.utils.EzPickle.__init__(self, command_range, **kwargs)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(COMMAND_INDEX + 1,), dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        command = (options or {}).get("command")
        if command is not None and not (isinstance(command, (int, float, np.number)) and math.isfinite(command)):
            raise ValueError(f"options['command'] must be a finite number (m/s), got {command!r}")
        self._given_command = None if command is None else float(command)
        return super().reset(seed=seed, options=options)

    def reset_model(self):
        super().reset_model()  # HalfCheetah-v4's start state, its draws first
        drawn = float(self.np_random.uniform(*self.command_range))
        self.command = drawn if self._given_command is None else self._given_command
        return self._get_obs()

    def step(self, action):
        observation, _, terminated, truncated, info = super().step(action)
        tracking = self.command - abs(info["x_velocity"] - self.command)
        info.update(command=self.command, reward_tracking=tracking)
        return observation, tracking + info["reward_ctrl"], terminated, truncated, info

    def _get_obs(self):
        return np.append(super()._get_obs(), self.command)


gym.register(id="HalfCheetahVelocity-v0", entry_point=HalfCheetahVelocity, max_episode_steps=1000)
