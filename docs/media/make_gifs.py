"""Make the README's small GIFs (docs/media/<example>.gif) from the examples' full-mode videos.

Run the examples first (``python examples/<example>.py``: they write outputs/<example>.mp4), then
``python docs/media/make_gifs.py [--out-dir outputs] [example ...]`` (default: all of them). Each GIF keeps at most MAX_FRAMES frames,
evenly spaced over the video, WIDTH pixels wide, in COLORS colours, and must stay under MAX_BYTES
(fewer frames are tried, down to MIN_FRAMES, until it does).
"""
import argparse
import os

import imageio.v3 as iio
import numpy as np
from PIL import Image

EXAMPLES = ("quickstart", "trajectory_optimization", "system_identification", "policy", "push_box",
            "material_identification", "soft_robot", "drone_flight", "jelly_slide", "sand_push",
            "coupling_identification")
MAX_FRAMES = 60
MIN_FRAMES = 20
WIDTH = 240  # pixels
COLORS = 128
MAX_BYTES = 300_000
HERE = os.path.dirname(os.path.abspath(__file__))


def make_gif(video, gif):
    """Write ``gif`` from the MP4 ``video`` with the most frames (≤ MAX_FRAMES, ≥ MIN_FRAMES) that
    keep it under MAX_BYTES. Returns the GIF's size in bytes."""
    frames, fps = iio.imread(video, index=None), iio.immeta(video)["fps"]
    for count in range(min(MAX_FRAMES, len(frames)), MIN_FRAMES - 1, -10):
        size = write_gif(frames, fps, count, gif)
        if size <= MAX_BYTES:
            break
    return size


def write_gif(frames, fps, count, gif):
    """Write ``gif`` from ``frames`` (n, h, w, 3) of a video at ``fps``: ``count`` frames evenly
    spaced, WIDTH px wide, COLORS colours shared by every frame, playing as long as the video.
    Returns its size in bytes."""
    keep = np.unique(np.linspace(0, len(frames) - 1, min(count, len(frames))).round().astype(int))
    height = round(frames.shape[1] * WIDTH / frames.shape[2])
    small = [Image.fromarray(frames[k]).resize((WIDTH, height), Image.LANCZOS) for k in keep]
    # one palette for the whole clip (from all its frames stacked), so colours do not flicker
    palette = Image.fromarray(np.concatenate([np.asarray(f) for f in small])).quantize(colors=COLORS)
    indexed = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in small]
    indexed[0].save(gif, save_all=True, append_images=indexed[1:], loop=0, optimize=True,
                    duration=round(1000.0 * len(frames) / fps / len(keep)))
    return os.path.getsize(gif)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out-dir", default="outputs", help="where the examples wrote their videos")
    parser.add_argument("examples", nargs="*", choices=EXAMPLES, default=EXAMPLES, metavar="example",
                        help=f"which GIFs to make (default: all of {', '.join(EXAMPLES)})")
    args = parser.parse_args()
    for name in args.examples:
        gif = os.path.join(HERE, f"{name}.gif")
        size = make_gif(os.path.join(args.out_dir, f"{name}.mp4"), gif)
        print(f"{gif}: {size / 1000:.0f} kB")
        if size > MAX_BYTES:
            raise SystemExit(f"{gif} is {size} bytes, over {MAX_BYTES}: fewer frames or a smaller width")


if __name__ == "__main__":
    main()
