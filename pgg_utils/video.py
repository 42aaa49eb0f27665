"""The sweep's videos (eval_gamma_sweep.py --video): one checkpoint's cell episode filmed at each γ as the sweep's
loop plays it (record_videos), frames labelled with γ and the return, and mp4 files of exactly those frames."""

import functools
import sys
from pathlib import Path

import numpy as np

from pgg_utils import scripts
from pgg_utils.arguments import DEFAULT_GAMMAS
from pgg_utils.cells import Task, task_error
from pgg_utils.checkpoints import find_checkpoints
from pgg_utils.checks import video_error
from pgg_utils.evaluation import EpisodeFault, EpisodeHooks, GuidedPolicy, evaluate_cell, first_line, read_checkpoint
from pgg_utils.files import InputError, replacing


@functools.cache
def label_font():
    """DejaVu Sans, which matplotlib ships and which has a γ (PIL's built-in bitmap font has none)."""
    import matplotlib
    from PIL import ImageFont

    return ImageFont.truetype(str(Path(matplotlib.get_data_path(), "fonts", "ttf", "DejaVuSans.ttf")), 20)


def labelled(frame: np.ndarray, text: str) -> np.ndarray:
    """`frame` with `text` written in its top-left corner and a grey line down its right edge."""
    from PIL import Image, ImageDraw

    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    box = draw.textbbox((10, 8), text, font=label_font())
    draw.rectangle((box[0] - 5, box[1] - 4, box[2] + 5, box[3] + 4), fill=(255, 255, 255))
    draw.text((10, 8), text, fill=(0, 0, 0), font=label_font())
    draw.line((image.width - 1, 0, image.width - 1, image.height), fill=(128, 128, 128), width=2)
    return np.asarray(image)


def write_video(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """An mp4 with exactly these frames (moviepy's clips can drop the last one to float rounding of
    their duration), through imageio's ffmpeg, which the [video] extra brings; written atomically."""
    import imageio.v2 as imageio

    with (
        replacing(path, tmp_suffix=".tmp" + Path(path).suffix) as tmp,
        imageio.get_writer(tmp, fps=fps, macro_block_size=1) as writer,
    ):
        for frame in frames:
            writer.append_data(frame)


# --- watching the knob: videos of one checkpoint at several γ ----------------------------------------


class Filming(EpisodeHooks):
    """Films one episode of a cell: its env, made by the script's make_env, renders, after the reset and after
    each of its steps."""

    def __init__(self, episode: int):
        self.episode, self.env, self.frames = episode, None, []

    def make_env(self, policy, episode: int):
        if episode != self.episode:
            return policy.make_env()
        self.env = policy.make_env(render_mode="rgb_array")
        return self.env

    def after_reset(self, obs: np.ndarray) -> None:
        self.frames.append(self.env.render())

    def after_step(self, episode: int, t: int, obs: np.ndarray, reward: float, done: bool, info: dict) -> None:
        if episode == self.episode:
            self.frames.append(self.env.render())


def record_episode(policy: GuidedPolicy, ckpt: dict, gamma: float, episodes: int, eval_seed: int, episode: int,
                   deterministic: bool, loop=evaluate_cell):  # fmt: skip
    """Episode `episode` of the sweep's cell of `episodes` episodes at `gamma`, filmed as the cell plays it
    (`loop`: evaluate_cell, or a copy of the sweep's own); returns (its frames, its return, the cell's returns)."""
    filming = Filming(episode)
    returns = loop(policy, ckpt, gamma, episodes, eval_seed, deterministic, filming)["return"]
    return filming.frames, float(returns[episode]), returns


def record_videos(args, loop=evaluate_cell) -> list[Path]:
    """eval_gamma_sweep.py --video (`args`: its Args, checked): one video per γ of one checkpoint, each the sweep's cell episode --video-episode (record_episode:
    the same reset seed and noise at every γ, and the return the cell gives it), and all of them side by side
    with γ and the return written on each panel (shorter episodes hold their last frame). Returns the files
    written."""
    checkpoints = find_checkpoints(args.paths, args.steps)
    if len(checkpoints) != 1:
        raise InputError(f"--video records one checkpoint; {len(checkpoints)} found "
                         "(name a checkpoint file, or narrow with --steps)")  # fmt: skip
    try:
        _, ckpt = read_checkpoint(checkpoints[0])
        agent, module, _ = scripts.load_agent(ckpt, checkpoints[0], tuple(Path(path).resolve() for path in args.script))
    except ValueError as e:
        raise InputError(f"{checkpoints[0]}: {e}") from None
    policy = GuidedPolicy(agent, ckpt, args.uniform_null, module)
    try:
        probe = policy.make_env(render_mode="rgb_array")
    except Exception as e:
        raise InputError(f"cannot make environment {ckpt['env_id']!r} ({first_line(e)})") from None
    changed = task_error(ckpt, Task(probe.observation_space, probe.action_space, ""))
    error = None if changed else video_error(probe)  # the training scripts' check: moviepy, a renderer
    fps = probe.metadata.get("render_fps") or 30
    probe.close()
    if changed:
        raise InputError(f"{checkpoints[0]}: {changed}")
    if error:
        raise InputError(error.replace("--capture-video", "--video"))
    output = Path(args.video)
    output.mkdir(parents=True, exist_ok=True)
    gammas = args.gammas if args.gammas is not None else DEFAULT_GAMMAS[ckpt["action_space"]]
    written, panels = [], []
    for gamma in gammas:
        try:
            frames, total, returns = record_episode(policy, ckpt, gamma, args.episodes, args.eval_seed,
                                                    args.video_episode, args.deterministic, loop)  # fmt: skip
        except EpisodeFault as e:
            raise InputError(f"{checkpoints[0]}: {e}") from None
        write_video(output / f"gamma_{gamma:g}.mp4", frames, fps)
        written.append(output / f"gamma_{gamma:g}.mp4")
        panels.append([labelled(frame, f"γ = {gamma:g}   return {total:.1f}") for frame in frames])
        print(f"γ = {gamma:g}: episode {args.video_episode}, return {total!r} over {len(frames) - 1} steps (its cell "
              f"of {args.episodes} episodes: mean return {returns.mean():.1f}) -> {written[-1]}", file=sys.stderr)  # fmt: skip
    longest = max(len(frames) for frames in panels)
    side_by_side = [
        np.concatenate([frames[min(t, len(frames) - 1)] for frames in panels], axis=1) for t in range(longest)
    ]
    write_video(output / "side_by_side.mp4", side_by_side, fps)
    return [*written, output / "side_by_side.mp4"]
