"""Examples double as tests: each runs in its short mode and ends with its own check; here we also
check that it left something to look at: a readable MP4 of moving frames and a readable PNG plot.
They run inside the test process (conftest's run_script)."""
import os

import imageio.v3 as iio
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# example → the plot it writes besides <example>.mp4
EXAMPLES = {"quickstart": "end_effector", "trajectory_optimization": "loss", "system_identification": "loss",
            "push_box": "loss", "material_identification": "fit", "policy": "loss", "soft_robot": "loss",
            "drone_flight": "loss", "jelly_slide": "loss", "sand_push": "loss", "coupling_identification": "fit"}
FLOAT32 = ("policy", "soft_robot")  # gs.init(precision="32"): in conftest's float32 group
SHORT_RES = (320, 240)  # examples/example_run.py: frames in short mode (width, height)
MIN_FRAMES = 10
MOVED = 30  # a pixel differs between the first and last frame by more than this (0-255): not codec noise


@pytest.mark.parametrize("name", [pytest.param(name, marks=[pytest.mark.float32] if name in FLOAT32 else [])
                                  for name in EXAMPLES])
def test_example_short(name, tmp_path, run_script):
    run_script(os.path.join(ROOT, "examples", f"{name}.py"), ["--short", "--out", str(tmp_path)])  # its check raises
    _check_video(tmp_path / f"{name}.mp4")
    _check_plot(tmp_path / f"{name}_{EXAMPLES[name]}.png")


def _check_video(path):
    """An MP4 imageio reads: at least MIN_FRAMES frames of SHORT_RES, and the scene moved."""
    frames = iio.imread(path, index=None)
    width, height = SHORT_RES
    assert frames.ndim == 4 and frames.shape[1:] == (height, width, 3), f"{path}: frames {frames.shape}"
    assert len(frames) >= MIN_FRAMES, f"{path}: {len(frames)} frames, expected ≥ {MIN_FRAMES}"
    changed = np.abs(frames[0].astype(int) - frames[-1].astype(int)).max(axis=-1) > MOVED
    assert changed.mean() > 1e-3, f"{path}: the first and last frames are the same picture"


def _check_plot(path):
    """A PNG imageio reads, with more than one colour in it."""
    image = iio.imread(path)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100, f"{path}: image {image.shape}"
    assert len(np.unique(image.reshape(-1, image.shape[-1]), axis=0)) > 2, f"{path}: a blank image"
