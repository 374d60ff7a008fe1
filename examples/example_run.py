"""What the examples share: their command line, what they leave in their output folder, and the
world position of a point fixed on a link.

``ExampleRun(__doc__, __file__)`` parses the command line of an example script:

* ``--short`` (or GS_EXAMPLES_SHORT=1): the quick CI run (fewer epochs, small frames, few of them);
* ``--out DIR``: the output folder, ``./outputs`` by default (created).

and writes the files named after the script into that folder: ``<script>.mp4``, a video of a
rollout seen by a camera (``camera`` + ``record``), and ``<script>_<what>.png``, a plot (``plot``;
matplotlib's Agg backend: no display needed). ``point_on_link`` is plain torch on the simulator's
outputs, so gradients flow through it. TARGET_COLOR and PENDULUM_VIEW keep the examples' pictures
alike.
"""
import argparse
import itertools
import os

import matplotlib

matplotlib.use("Agg")  # headless: no display, no GUI toolkit
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
from matplotlib.ticker import MaxNLocator  # noqa: E402
import torch  # noqa: E402

RES, SHORT_RES = (640, 480), (320, 240)  # camera frames (width, height), pixels
FPS = 30  # frames per second of the videos
SHORT_EVERY = 5  # short mode films every 5th step (full mode: every step)
HOLD_S = 0.5  # seconds the last frame stays on screen, so the final pose can be seen
TARGET_COLOR = (0.2, 0.8, 0.3)  # debug spheres marking targets and observations
PENDULUM_VIEW = ((0.55, 1.65, 0.2), (0.0, 0.1, -0.45))  # camera pos, lookat (m): assets/pendulum2.urdf's swing
# plane (x, z), seen from the side the rasterizer's sun lights


class ExampleRun:
    """One run of an example script: ``short`` (bool), ``out`` (output folder, created) and ``name``
    (the script's file name without .py, which names its output files)."""

    def __init__(self, doc, script):
        parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
        parser.add_argument("--short", action="store_true", help="quick CI run (also: GS_EXAMPLES_SHORT=1)")
        parser.add_argument("--out", default="outputs", metavar="DIR",
                            help="folder of the video and plot (default: ./outputs; created)")
        args = parser.parse_args()
        self.short = args.short or os.environ.get("GS_EXAMPLES_SHORT", "0") not in ("", "0")
        self.out = args.out
        self.name = os.path.splitext(os.path.basename(script))[0]
        os.makedirs(self.out, exist_ok=True)

    def path(self, suffix):
        """Path of the output file ``<out>/<name><suffix>``."""
        return os.path.join(self.out, self.name + suffix)

    def camera(self, scene, pos, lookat, fov=40):
        """A headless camera of ``scene`` at ``pos`` looking at ``lookat`` (world, m), z up, vertical
        field of view ``fov`` degrees; RES frames, SHORT_RES in short mode. It also draws the scene's
        debug spheres (targets)."""
        res = SHORT_RES if self.short else RES
        return scene.add_camera(res=res, pos=pos, lookat=lookat, up=(0.0, 0.0, 1.0), fov=fov, GUI=False,
                                debug=True)

    def record(self, camera, rollout):
        """Run ``rollout(after_step)`` without gradients, ``camera`` rendering a frame at each call of
        ``after_step`` (the rollout calls it after each scene.step; in short mode at every
        SHORT_EVERY-th call only), then HOLD_S s more of the last state; writes ``<out>/<name>.mp4``
        at FPS. Returns (what rollout returned, the video's path)."""
        every = SHORT_EVERY if self.short else 1
        calls = itertools.count(1)

        def after_step():
            if next(calls) % every == 0:
                camera.render()

        camera.start_recording()
        with torch.no_grad():
            result = rollout(after_step)
        for _ in range(round(HOLD_S * FPS)):
            camera.render()
        path = self.path(".mp4")
        camera.stop_recording(save_to_filename=path, fps=FPS)
        return result, path

    def plot(self, what, curves, xlabel, ylabel, title, log_y=False, targets=None):
        """Write the line plot ``<out>/<name>_<what>.png``; returns its path.

        curves: {label: y values (T,)} drawn against 0 … T − 1; targets: {label of a curve: y value},
        a dashed horizontal line in that curve's colour; log_y: logarithmic y axis (losses)."""
        fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
        for k, (label, values) in enumerate(curves.items()):
            ax.plot(torch.as_tensor(values).cpu().numpy(), color=f"C{k}", label=label)
            if targets and label in targets:
                ax.axhline(float(targets[label]), color=f"C{k}", linestyle="--", label=f"{label} target")
        if log_y:
            ax.set_yscale("log")
        ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # epochs, steps: whole numbers
        ax.grid(True, alpha=0.3)
        if len(curves) > 1 or targets:
            ax.legend()
        fig.tight_layout()
        path = self.path(f"_{what}.png")
        fig.savefig(path)
        plt.close(fig)
        return path


def point_on_link(link, offset):
    """World position (3,) m of the point at ``offset`` (3,) m in ``link``'s frame:
    pos + rotate(quat, offset), with the link's world pose (quat: w, x, y, z)."""
    quat = link.get_quat()
    w, u = quat[..., :1], quat[..., 1:]
    t = 2.0 * torch.cross(u, offset.expand_as(u), dim=-1)
    return link.get_pos() + offset + w * t + torch.cross(u, t, dim=-1)


def check_loss_drop(losses, required_drop, name):
    """The example's self-check: every loss finite and the last ≥ required_drop× below the first."""
    if not all(torch.isfinite(torch.tensor(losses))):
        raise AssertionError(f"a loss is not finite: {losses}")
    if not losses[-1] * required_drop <= losses[0]:
        raise AssertionError(f"the loss must fall ≥ {required_drop:.0f}×: {losses[0]:.4e} → {losses[-1]:.4e} "
                             f"({losses[0] / losses[-1]:.1f}×)")
    print(f"{name} OK (≥ {required_drop:.0f}× drop)")
