"""Video files of a camera's frames: MP4 (H.264 through imageio-ffmpeg) or GIF (imageio, Pillow).

A Recording takes the camera's frames one by one, in one of two ways (Camera.start_recording
says which the user picks):

- streamed, when the file and frame rate are known as recording starts (Genesis 1.4.5's
  ``start_recording(save_to_filename, fps)``): each frame is queued to a writer thread that pipes
  it to ffmpeg, which encodes in its own process while the caller goes on rendering; memory stays
  bounded (QUEUE_FRAMES frames at most wait);
- buffered, when the file is named as recording stops (``stop_recording(save_to_filename, fps)``):
  the frames are encoded all the same as they come, into a temporary raw H.264 stream, and kept in
  memory too (the camera hands over fresh uint8 arrays: no copy) in case a GIF is asked for. An MP4
  is then that stream wrapped at the frame rate given (no re-encoding: milliseconds); encoding it
  all at the end cost 1.8–4.5 ms a frame, up to +29 % on a rendered rollout.

MP4: libx264, yuv420p so that every player reads it; yuv420p needs an even width and height, so an
odd one gets a black column or row of padding. Preset ultrafast (crf 23): 2 ms a 640×480 frame on
2 cores, half of veryfast's, for files ~6× larger (260 kB for bench/render.py's 300 KUKA frames).
GIF: looped, each frame shown for 1/fps s rounded to the format's unit, a hundredth of a second,
and at least two (browsers show a shorter delay as a tenth of a second: 60 fps plays at 50); its
frames wait in memory until the file is written (Pillow writes a GIF at once, truncating a
delay to its unit: it is given rounded; it also merges equal consecutive frames into one shown
as long, so a reader may get fewer frames than were recorded, playing the same).
"""
import logging
import os
import queue
import subprocess
import tempfile
import threading
import weakref
from fractions import Fraction

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np

from ..solvers.core import AssetError, InvalidInputError

VIDEO_EXTENSIONS = (".mp4", ".gif")
DEFAULT_FPS = 60  # Genesis's
QUEUE_FRAMES = 8
_X264 = ["-preset", "ultrafast", "-crf", "23"]
_EVEN = ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]


def check_target(owner, filename, fps):
    """(filename, fps) checked: a path ending in .mp4 or .gif in an existing folder, fps a positive
    finite number (None: DEFAULT_FPS)."""
    if not isinstance(filename, (str, os.PathLike)) or os.path.splitext(os.fspath(filename))[1].lower() \
            not in VIDEO_EXTENSIONS:
        raise InvalidInputError(f"{owner}: argument 'save_to_filename' must be a path ending in one of "
                                f"{VIDEO_EXTENSIONS}, got {filename!r}")
    filename = os.fspath(filename)
    folder = os.path.dirname(os.path.abspath(filename))
    if not os.path.isdir(folder):
        raise InvalidInputError(f"{owner}: argument 'save_to_filename' must be in an existing folder, got "
                                f"{filename!r} ({folder} does not exist)")
    if os.path.isdir(filename):
        raise InvalidInputError(f"{owner}: argument 'save_to_filename' must name a file, got {filename!r}, a folder")
    _check_writable(owner, filename)
    fps = DEFAULT_FPS if fps is None else fps
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not 0 < fps < np.inf:
        raise InvalidInputError(f"{owner}: argument 'fps' must be a positive number of frames per second, got {fps!r}")
    return filename, float(fps)


def _check_writable(owner, filename):
    """Open ``filename`` for appending, as a probe (a file it creates is removed again): a folder
    the user may not write to, or a read-only one, raises here, not in the encoder (which says
    nothing: ffmpeg's exit status is not checked) or at the scene's step."""
    existed = os.path.exists(filename)
    try:
        with open(filename, "ab"):
            pass
    except OSError as error:
        raise InvalidInputError(f"{owner}: argument 'save_to_filename' must be a file that can be written, got "
                                f"{filename!r} ({error.strerror})") from error
    if not existed:
        os.remove(filename)


class _Mp4Writer:
    """Frames (H, W, 3) uint8 piped to an ffmpeg process writing an H.264 MP4 (raw: a bare H.264
    stream, for mux_h264)."""

    def __init__(self, filename, fps, res, raw=False):
        self._filename = filename
        width, height = res
        extra = (_EVEN if width % 2 or height % 2 else []) + (["-f", "h264"] if raw else [])
        self._encoder = imageio_ffmpeg.write_frames(filename, (width, height), fps=fps, codec="libx264",
                                                    pix_fmt_in="rgb24", pix_fmt_out="yuv420p", quality=None,
                                                    macro_block_size=1, output_params=_X264 + extra,
                                                    ffmpeg_log_level="error")
        self._encoder.send(None)  # starts ffmpeg

    def write(self, frame):
        self._encoder.send(frame)

    def close(self):
        self._encoder.close()
        # (imageio-ffmpeg does not check ffmpeg's exit status: a file it could not write is silent)
        if not os.path.exists(self._filename) or os.path.getsize(self._filename) == 0:
            raise OSError(f"ffmpeg wrote nothing to {self._filename!r}")


class _GifWriter:
    """Frames (H, W, 3) uint8 gathered, then written as one looped GIF on close."""

    def __init__(self, filename, fps, res):
        self._filename, self._fps, self._frames = filename, fps, []

    def write(self, frame):
        self._frames.append(frame)

    def close(self):
        delay = 10 * max(2, round(100.0 / self._fps))  # ms
        iio.imwrite(self._filename, np.stack(self._frames), extension=".gif", duration=delay, loop=0)


def mux_h264(raw, filename, fps):
    """The MP4 ``filename`` from the raw H.264 stream in the file ``raw``, at ``fps`` frames/s,
    without re-encoding, in two passes: the stream's own timing (x264 wrote the rate it encoded at)
    rewritten to fps, then the frames wrapped with timestamps at fps. (Rewritten while wrapping, the
    demuxer had already timed the last frame from the old rate: above 60 fps it lasted 1/50 s or so,
    and readers decoded extra frames, 28 for 12 at 1000 fps.)"""
    tick = Fraction(2 * fps).limit_denominator(1_000_000)  # H.264 counts two ticks a frame
    ffmpeg = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error"]
    timed = raw + ".timed.h264"
    try:
        subprocess.run(ffmpeg + ["-i", raw, "-c", "copy", "-bsf:v",
                                 f"h264_metadata=tick_rate={tick.numerator}/{tick.denominator}", "-f", "h264", timed],
                       check=True, capture_output=True)
        subprocess.run(ffmpeg + ["-r", str(fps), "-i", timed, "-c", "copy", filename], check=True, capture_output=True)
    finally:
        _remove(timed)


def _open_writer(filename, fps, res):
    return (_GifWriter if filename.lower().endswith(".gif") else _Mp4Writer)(filename, fps, res)


class _Stream:
    """A writer fed from a thread, in order; the first error it meets is raised by the next put or close."""

    def __init__(self, writer):
        self._writer, self._error = writer, None
        self._queue = queue.Queue(maxsize=QUEUE_FRAMES)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while (frame := self._queue.get()) is not None:
            if self._error is None:
                try:
                    self._writer.write(frame)
                except Exception as error:  # ffmpeg gone, disk full...: kept for the caller
                    self._error = error

    def put(self, frame):
        if self._error is not None:
            raise self._error
        self._queue.put(frame)

    def close(self):
        self._queue.put(None)
        self._thread.join()
        if self._error is not None:
            raise self._error
        self._writer.close()


class Recording:
    """The frames of one recording of a camera ``owner`` (its name, for messages) whose images are
    ``res`` (width, height); streamed to ``filename`` at ``fps`` when a filename is given, else
    buffered until ``save``."""

    def __init__(self, owner, res, filename=None, fps=None):
        self.owner, self.res, self.n_frames = owner, res, 0
        self.skipped = 0  # frames a streamed recording left out (the state to draw was not finite)
        self.streamed = filename is not None
        self._frames = []
        if self.streamed:
            self.filename, self.fps = check_target(owner, filename, fps)
            self._stream = _Stream(self._writer(self.filename, self.fps))
        else:  # encoded meanwhile into a temporary raw stream (removed when saved, dropped or collected)
            handle, self._raw = tempfile.mkstemp(suffix=".h264")
            os.close(handle)
            self._remove_raw = weakref.finalize(self, _remove, self._raw)
            self._stream = _Stream(self._writer(self._raw, DEFAULT_FPS, raw=True))

    def _writer(self, filename, fps, raw=False):
        try:
            return _Mp4Writer(filename, fps, self.res, raw) if raw else _open_writer(filename, fps, self.res)
        except Exception as error:
            raise AssetError(f"{self.owner}: cannot write video file {filename!r}: {error}") from error

    def add(self, frame):
        """Append a frame: (H, W, 3) uint8, not modified afterwards by the caller."""
        if not self.streamed:
            self._frames.append(frame)
        try:
            self._stream.put(frame)
        except Exception as error:
            target = self.filename if self.streamed else self._raw
            raise AssetError(f"{self.owner}: writing video file {target!r} failed: {error}") from error
        self.n_frames += 1

    def target(self, filename=None, fps=None):
        """The (file, fps) save writes: the ones named at start (both arguments must then be None),
        else the arguments, checked (filename must then be given). Changes nothing."""
        if not self.streamed:
            return check_target(self.owner, filename, fps)
        if filename is not None or fps is not None:
            raise InvalidInputError(f"{self.owner}: stop_recording arguments 'save_to_filename' and 'fps' must be "
                                    f"None for a recording started with a filename ({self.filename!r}), got "
                                    f"{filename!r} and {fps!r}")
        return self.filename, self.fps

    def save(self, filename, fps):
        """Finish the file (filename, fps), as target() gave them: close the stream, or encode the
        kept frames."""
        if self.streamed:
            self._finish(self._stream.close, filename)
            return

        def write():
            self._stream.close()
            if filename.lower().endswith(".mp4"):
                mux_h264(self._raw, filename, fps)
            else:
                writer = _open_writer(filename, fps, self.res)
                for frame in self._frames:
                    writer.write(frame)
                writer.close()
        try:
            self._finish(write, filename)
        finally:
            self._frames = []
            self._remove_raw()

    def discard(self):
        """Drop the recording: its encoder stops (a streamed one's too: its ffmpeg process would
        outlive the scene) and no file is left (a streamed one without frames: ffmpeg's header
        alone, no valid video)."""
        encoder_log = logging.getLogger("imageio_ffmpeg")  # (it warns that a video without frames is invalid)
        level = encoder_log.level
        encoder_log.setLevel(logging.ERROR)
        try:
            self._stream.close()
        except Exception:  # nothing is kept of it: an encoder's failure does not matter any more
            pass
        finally:
            encoder_log.setLevel(level)
        self._frames = []
        if not self.streamed:
            self._remove_raw()
        elif not self.n_frames:
            _remove(self.filename)

    def _finish(self, finish, filename):
        try:
            finish()
        except Exception as error:
            raise AssetError(f"{self.owner}: writing video file {filename!r} failed: {error}") from error


def _remove(path):
    if os.path.exists(path):
        os.remove(path)
