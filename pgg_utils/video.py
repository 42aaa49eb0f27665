"""Writing the sweep's videos: frames labelled with γ and the return, and mp4 files of exactly those frames."""

import functools
from pathlib import Path

import numpy as np

from pgg_utils.files import replacing


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
