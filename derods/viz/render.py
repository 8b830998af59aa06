"""Off-screen rendering of worlds to images and videos, headless by default.

MuJoCo renders through OpenGL; on a machine without a display derods selects
the EGL backend (``MUJOCO_GL=egl``, Mesa on the CPU) before MuJoCo's
renderer is first imported. Videos are written with mediapy, whose ffmpeg
comes from imageio-ffmpeg when the system has none, to a temporary file next
to the target that replaces the target only when complete: a crash or Ctrl-C
never leaves a half-written video behind.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import shutil
import sys
import tempfile

import numpy as np


def add_backdrop(spec, width: int = 1280, height: int = 720) -> None:
    """Give an MjSpec a pale sky, soft headlight and an offscreen buffer of at least
    width x height [pixels], for pictures of scenes that set none."""
    import mujoco

    spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, width)
    spec.visual.global_.offheight = max(spec.visual.global_.offheight, height)
    spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
    spec.visual.headlight.diffuse = [0.55, 0.55, 0.55]
    spec.add_texture(name="derods_sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=[0.97, 0.98, 1.0],
                     rgb2=[0.82, 0.87, 0.94], width=64, height=64)


def ensure_headless_gl() -> None:
    """Use EGL unless a display exists or the user chose a backend (MUJOCO_GL)."""
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY") and sys.platform.startswith("linux"):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _ffmpeg_for_mediapy():
    import mediapy

    if shutil.which("ffmpeg") is None:
        import imageio_ffmpeg

        mediapy.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())
    return mediapy


def check_output_path(out) -> pathlib.Path:
    """The output path, after checking that its folder exists; raises ValueError with the fix."""
    out = pathlib.Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"output folder {str(out.parent)!r} does not exist; create it or pass another --out")
    return out


class Camera:
    """An off-screen renderer of a MuJoCo model.

    model: the ``mujoco.MjModel``. width, height: image size [pixels].
    camera: a camera name or id of the model, a ``mujoco.MjvCamera``, or None for
        MuJoCo's default free camera.
    """

    def __init__(self, model, width: int, height: int, camera=None):
        ensure_headless_gl()
        import mujoco

        backend = os.environ.get("MUJOCO_GL", "glfw").lower()
        if backend == "glfw" and not os.environ.get("DISPLAY") and sys.platform.startswith("linux"):
            raise ValueError(
                "no display and MuJoCo was imported before derods chose a headless backend; "
                "set MUJOCO_GL=egl (or import derods before mujoco)"
            )

        for name, val in (("width", width), ("height", height)):
            if int(val) != val or val <= 0:
                raise ValueError(f"{name} must be a positive integer [pixels], got {val!r}")
        offw, offh = model.vis.global_.offwidth, model.vis.global_.offheight
        if width > offw or height > offh:
            raise ValueError(
                f"image {width}x{height} is larger than the model's offscreen buffer {offw}x{offh}; "
                f'add <visual><global offwidth="{width}" offheight="{height}"/></visual> to the MJCF '
                "or ask for a smaller image"
            )
        if isinstance(camera, str):
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
                names = [model.camera(i).name for i in range(model.ncam)]
                raise ValueError(f"unknown camera {camera!r}; the scene has {names or 'none'}")
        self.model = model
        self.camera = -1 if camera is None else camera
        self.renderer = mujoco.Renderer(model, height, width)

    def render(self, data, scene_callback=None) -> np.ndarray:
        """An RGB image, shape (height, width, 3), uint8.

        scene_callback: optional ``f(scene)`` that adds geoms (overlays) to the
        ``mujoco.MjvScene`` before rendering.
        """
        self.renderer.update_scene(data, camera=self.camera)
        if scene_callback is not None:
            scene_callback(self.renderer.scene)
        return self.renderer.render()

    def close(self) -> None:
        self.renderer.close()


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


class VideoWriter:
    """Streams frames to an MP4 that appears at ``out`` only once complete.

    Use as a context manager: ``with VideoWriter(out, (h, w), fps) as vw: vw.add(img)``.
    """

    def __init__(self, out, shape: tuple[int, int], fps: float):
        self.out = check_output_path(out)
        if not (fps > 0):
            raise ValueError(f"fps must be > 0, got {fps!r}")
        self.shape, self.fps = shape, fps
        self.frames = 0

    def __enter__(self):
        mediapy = _ffmpeg_for_mediapy()
        self._atomic = atomic_output(self.out)
        tmp = self._atomic.__enter__()
        self._writer = mediapy.VideoWriter(tmp, shape=self.shape, fps=self.fps)
        self._writer.__enter__()
        return self

    def add(self, image: np.ndarray) -> None:
        self._writer.add_image(image)
        self.frames += 1

    def __exit__(self, *exc):
        self._writer.__exit__(*exc)
        return self._atomic.__exit__(*exc)


def write_image(out, image: np.ndarray) -> pathlib.Path:
    """Write a PNG atomically; returns the path."""
    out = check_output_path(out)
    mediapy = _ffmpeg_for_mediapy()
    with atomic_output(out) as tmp:
        mediapy.write_image(tmp, image)
    return out


def film(world, out, seconds: float, fps: float, width: int, height: int, camera=None, paint=None,
         before_step=None, progress: bool = True, label: str = "film") -> int:
    """Step a :class:`derods.world.World` for ``seconds`` and write what ``camera`` sees to an MP4.

    paint: optional scene callback (overlays). before_step: optional ``f(world)``
    called before every step (to move clamps, set controls). Shows a
    progress bar. Returns the number of frames; the video appears only when complete.
    """
    from tqdm import tqdm

    out = check_output_path(out)
    dt = world.model.opt.timestep
    n_frames = max(1, int(round(seconds * fps)))
    steps_per_frame = max(1, int(round(1.0 / (fps * dt))))
    cam = Camera(world.model, width, height, camera)
    try:
        with VideoWriter(out, (height, width), fps) as video:
            video.add(cam.render(world.data, paint))
            for _ in tqdm(range(n_frames - 1), desc=label, unit="frame", disable=not progress, leave=False):
                if before_step is None:
                    world.step(steps_per_frame)
                else:
                    for _ in range(steps_per_frame):
                        before_step(world)
                        world.step()
                video.add(cam.render(world.data, paint))
    finally:
        cam.close()
    return video.frames
