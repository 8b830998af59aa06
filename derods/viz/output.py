"""What derods writes to disk: output paths checked before any work, and PNG images and
MP4 videos written atomically.

Files are written to a temporary name next to the target and moved onto it only when
complete: a crash, Ctrl-C or kill never leaves a partial file. Videos are encoded by
imageio-ffmpeg's ffmpeg, which ignores the terminal's Ctrl-C.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pathlib
import tempfile

import numpy as np

#: Still images and videos derods writes.
IMAGE_SUFFIXES = (".png",)
VIDEO_SUFFIXES = (".mp4",)


def check_output_path(out, suffixes: tuple[str, ...] | None = None, what: str = "output") -> pathlib.Path:
    """The output path, checked before any work: its folder exists and is writable, it is not
    a folder, and (if ``suffixes``) it ends in one of them. Raises ValueError with the fix."""
    out = pathlib.Path(out)
    if out.is_dir():
        raise ValueError(f"{what} {str(out)!r} is a folder; give a file name, e.g. {str(out / ('out' + (suffixes or ('.mp4',))[0]))!r}")
    if suffixes and out.suffix.lower() not in suffixes:
        raise ValueError(f"{what} {str(out)!r} must end in {' or '.join(suffixes)}"
                         + (f" (got {out.suffix!r})" if out.suffix else " (it has no extension)"))
    if not out.parent.is_dir():
        raise ValueError(f"output folder {str(out.parent)!r} does not exist; create it or pass another path")
    try:  # a real write: permissions alone do not tell (root, read-only or special file systems)
        with tempfile.TemporaryFile(dir=out.parent):
            pass
    except OSError as err:
        raise ValueError(f"output folder {str(out.parent)!r} is not writable ({err.strerror}); pass another path") from None
    return out


def check_outputs(out, still=None) -> tuple:
    """The video and still paths, checked before any work: an .mp4 and a .png in writable
    folders, and not the same file. Raises ValueError with the fix."""
    out = check_output_path(out, VIDEO_SUFFIXES, "--out")
    if still is not None:
        still = check_output_path(still, IMAGE_SUFFIXES, "--still")
        if still.resolve() == out.resolve():
            raise ValueError(f"--still {str(still)!r} is the video's path; give the still another name")
    return out, still


@contextlib.contextmanager
def atomic_output(out: pathlib.Path):
    """Yield a temporary path next to ``out``; move it onto ``out`` only on success."""
    out = pathlib.Path(out)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=out.suffix, dir=out.parent)
    os.close(fd)
    try:
        yield pathlib.Path(tmp)
        # mkstemp makes the file private (0600); give it the permissions of a new file.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, out)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise


def mediapy():
    """mediapy, told where ffmpeg is (imageio-ffmpeg's when the system has none), for
    reading videos back."""
    import shutil

    import mediapy as mp

    if shutil.which("ffmpeg") is None:
        import imageio_ffmpeg

        mp.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())
    return mp


def write_image(out, image: np.ndarray) -> pathlib.Path:
    """Write a PNG atomically; returns the path. image: RGB, shape (height, width, 3), uint8."""
    import mediapy

    out = check_output_path(out, IMAGE_SUFFIXES, "image")
    with atomic_output(out) as tmp:
        mediapy.write_image(tmp, image, fmt="png")
    return out


class VideoWriter:
    """Streams RGB frames (height, width, 3) to an MP4 (H.264) that appears at ``out`` only
    once complete. ``with VideoWriter(out, (h, w), fps) as vw: vw.add(img)``."""

    def __init__(self, out, shape: tuple[int, int], fps: float):
        self.out = check_output_path(out, VIDEO_SUFFIXES, "video")
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be finite and > 0 [1/s], got {fps!r}")
        self.shape, self.fps = shape, float(fps)
        self.frames = 0

    def __enter__(self):
        import imageio_ffmpeg

        self._atomic = atomic_output(self.out)
        tmp = self._atomic.__enter__()
        h, w = self.shape
        # macro_block_size 2: H.264 in yuv420p needs even sizes, nothing more.
        self._gen = imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=self.fps, quality=6, macro_block_size=2,
                                                ffmpeg_log_level="error")
        self._gen.send(None)
        return self

    def add(self, image: np.ndarray) -> None:
        self._gen.send(np.ascontiguousarray(image))
        self.frames += 1

    def __exit__(self, *exc):
        # On an abort (Ctrl-C before the first frame, say) the temporary file is deleted, so
        # imageio-ffmpeg's warning that the video it closes holds no frame is noise.
        quiet = exc[0] is not None
        logger = logging.getLogger("imageio_ffmpeg")
        level = logger.level
        try:
            if quiet:
                logger.setLevel(logging.ERROR)
            self._gen.close()
        finally:
            logger.setLevel(level)
            return self._atomic.__exit__(*exc)

