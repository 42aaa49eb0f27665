"""A training script's agent from its checkpoint: the one loader behind both scripts' `agent_from_checkpoint` and
`load_checkpoint` (`script_loaders`), so that a fork's loads with the fork's own `make_agent` and the same checks."""

from pathlib import Path

from pgg_utils import checkpoints, scripts


def agent_from_checkpoint(script, ckpt: dict, source: str | Path = "checkpoint"):
    """The agent, in eval mode, of a loaded checkpoint dict (of any readable format), built by `script` (a training
    script's module: its ACTION_SPACE, file and make_agent) once the checkpoint is shown to be that script's, finite."""
    scripts.require_own(ckpt, script.ACTION_SPACE, script.__file__, source)
    checkpoints.require_finite(ckpt, source)
    shapes = ckpt
    if script.ACTION_SPACE == "continuous":  # one saved before the bounds were recorded takes the task's
        low, high = checkpoints.action_bounds(ckpt)
        shapes = {**ckpt, "action_low": low, "action_high": high}
    agent = script.make_agent(ckpt["args"], shapes)
    agent.load_state_dict(ckpt["model"])
    return agent.eval()


def load_checkpoint(script, path) -> tuple:
    """(agent in eval mode, normalisation statistics included; the checkpoint dict) from a file, by `script`.
    FileNotFoundError, one line, where there is no such file (a relative path read from another folder)."""
    if not Path(path).is_file():
        relative = "" if Path(path).is_absolute() else f" (relative to {Path.cwd()})"
        raise FileNotFoundError(f"no such checkpoint file: {path}{relative}")
    ckpt = checkpoints.read_checkpoint_file(path)
    return script.agent_from_checkpoint(ckpt, path), ckpt


def script_loaders(script) -> tuple:
    """(agent_from_checkpoint, load_checkpoint) of `script`, a training script's module: the two above, bound to it,
    as the script exposes them (`agent, ckpt = ppo_pgg_continuous.load_checkpoint(path)`)."""

    def script_agent_from_checkpoint(ckpt: dict, source: str | Path = "checkpoint"):
        """The agent, in eval mode, of a loaded checkpoint dict (of any readable format), by this script's make_agent."""
        return agent_from_checkpoint(script, ckpt, source)

    def script_load_checkpoint(path) -> tuple:
        """(agent in eval mode, the checkpoint dict) from a checkpoint file, by this script's make_agent."""
        return load_checkpoint(script, path)

    return script_agent_from_checkpoint, script_load_checkpoint
