"""Off-screen rendering of worlds to images and videos, headless by default.

MuJoCo renders through OpenGL. derods makes its own GL context when a renderer
is first made: the backend the user chose (``MUJOCO_GL``), else EGL (Mesa on the
CPU) on a Linux machine without a display, else MuJoCo's default. Importing
derods or MuJoCo sets nothing.

Quality: on software GL (Mesa's llvmpipe) a 960x540 frame with a 4096 shadow
map, 4x MSAA and floor reflections costs ~250 ms of CPU; ``quality="fast"``
(shadow map 1024, no MSAA, no reflections) ~50 ms and looks nearly the same
(docs/render_quality.png). ``"auto"`` (the default) picks "fast" on software GL
and the scene's own settings ("full") on a GPU.

Videos: :func:`film` steps the world in the calling thread while a second thread
draws the frames and pipes them to ffmpeg (MuJoCo's step and its renderer both
release the GIL), through imageio-ffmpeg, whose ffmpeg ignores the terminal's
Ctrl-C. Files are written to a temporary name next to the target and moved
onto it only when complete: a crash, Ctrl-C or kill never leaves a partial file.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pathlib
import queue
import sys
import tempfile
import threading

import numpy as np

#: Render settings by quality: (shadow map size [pixels], MSAA samples, floor reflections).
QUALITIES = {"fast": (1024, 0, False), "full": None}
#: GL renderers that run on the CPU, where "auto" picks "fast".
SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast", "swiftshader")
#: Still images and videos derods writes.
IMAGE_SUFFIXES = (".png",)
VIDEO_SUFFIXES = (".mp4",)


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


def _headless() -> bool:
    return (sys.platform.startswith("linux") and not os.environ.get("DISPLAY")
            and not os.environ.get("WAYLAND_DISPLAY"))


def gl_context(width: int, height: int):
    """A GL context for off-screen rendering, made current: the user's ``MUJOCO_GL``
    backend, else EGL without a display, else MuJoCo's default."""
    if "MUJOCO_GL" not in os.environ and _headless():
        from mujoco.egl import GLContext
    else:
        from mujoco import GLContext
    ctx = GLContext(width, height)
    ctx.make_current()
    return ctx


def _is_software_gl() -> bool:
    try:
        from OpenGL import GL

        name = (GL.glGetString(GL.GL_RENDERER) or b"").decode(errors="replace").lower()
    except Exception:  # no PyOpenGL or no current context: assume a GPU, keep the scene's look
        return False
    return any(s in name for s in SOFTWARE_GL)


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


class View:
    """What a camera sees of a model, built into MuJoCo scenes in the calling thread.

    camera: a camera name or id of the model, a ``mujoco.MjvCamera``, or None for
    MuJoCo's default free camera. ``n_scenes`` scenes are kept, so that one can be drawn
    while the next is built, each of up to ``max_geom`` geoms. draw_flexes: False leaves
    the rods' flexes out (their collision capsules; :func:`derods.viz.overlay.rod_lines`
    draws rods cheaply).
    """

    def __init__(self, model, camera=None, n_scenes: int = 1, max_geom: int = 10000, draw_flexes: bool = True):
        import mujoco

        if isinstance(camera, str) and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
            names = [model.camera(i).name for i in range(model.ncam)]
            raise ValueError(f"unknown camera {camera!r}; the scene has {names or 'none'}")
        self.model = model
        self.option = mujoco.MjvOption()
        if isinstance(camera, mujoco.MjvCamera):
            self.camera = camera
        else:
            self.camera = mujoco.MjvCamera()
            if camera is None:
                mujoco.mjv_defaultFreeCamera(model, self.camera)
            else:
                self.camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
                self.camera.fixedcamid = (camera if isinstance(camera, int)
                                          else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera))
        if not draw_flexes:
            for flag in ("mjVIS_FLEXEDGE", "mjVIS_FLEXVERT", "mjVIS_FLEXFACE", "mjVIS_FLEXSKIN"):
                self.option.flags[getattr(mujoco.mjtVisFlag, flag)] = 0
        self.scenes = [mujoco.MjvScene(model, maxgeom=max_geom) for _ in range(n_scenes)]

    def build(self, data, paint=None, index: int = 0):
        """Fill scene ``index`` with the model at ``data`` (and ``paint(scene)``'s overlays)."""
        import mujoco

        scene = self.scenes[index]
        mujoco.mjv_updateScene(self.model, data, self.option, None, self.camera, mujoco.mjtCatBit.mjCAT_ALL, scene)
        if paint is not None:
            paint(scene)
        return scene


class Raster:
    """Draws MuJoCo scenes into RGB images in the thread that made it (GL is per thread).

    quality: "auto", "fast" or "full" (see the module docstring). Make it in the thread
    that will draw; :meth:`close` in that thread too.
    """

    def __init__(self, model, width: int, height: int, quality: str = "auto"):
        import mujoco

        check_frame_size(model, width, height)
        if quality not in ("auto",) + tuple(QUALITIES):
            raise ValueError(f"quality must be one of {('auto',) + tuple(QUALITIES)}, got {quality!r}")
        self.ctx = gl_context(width, height)
        if quality == "auto":
            quality = "fast" if _is_software_gl() else "full"
        self.quality = quality
        q = model.vis.quality
        saved = (q.shadowsize, q.offsamples)
        settings = QUALITIES[quality]
        if settings is not None:
            q.shadowsize, q.offsamples = min(q.shadowsize, settings[0]), settings[1]
        try:
            self.con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        finally:
            q.shadowsize, q.offsamples = saved
        self.reflection = True if settings is None else settings[2]
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.con)
        self.rect = mujoco.MjrRect(0, 0, width, height)
        self.image = np.empty((height, width, 3), dtype=np.uint8)

    def draw(self, scene) -> np.ndarray:
        """The scene as an RGB image, shape (height, width, 3), uint8 (a new array)."""
        import mujoco

        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = self.reflection
        mujoco.mjr_render(self.rect, scene, self.con)
        mujoco.mjr_readPixels(self.image, None, self.rect, self.con)
        return np.flipud(self.image).copy()

    def close(self) -> None:
        self.con.free()
        self.ctx.free()


def check_frame_size(model, width: int, height: int) -> None:
    """Refuse a frame size that is not a positive integer or exceeds the model's offscreen
    buffer, naming the MJCF line that fixes it."""
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


class Camera:
    """An off-screen renderer of a model in the calling thread: a :class:`View` and a
    :class:`Raster`. width, height [pixels]; camera as for :class:`View`; quality as for
    :class:`Raster`."""

    def __init__(self, model, width: int, height: int, camera=None, quality: str = "auto"):
        self.view = View(model, camera)
        self.raster = Raster(model, width, height, quality)

    def render(self, data, scene_callback=None) -> np.ndarray:
        """An RGB image, shape (height, width, 3), uint8; scene_callback(scene) adds overlays."""
        return self.raster.draw(self.view.build(data, scene_callback))

    def close(self) -> None:
        self.raster.close()


class _Drawer(threading.Thread):
    """Draws scenes handed over by :func:`film` and feeds them to a sink, in its own thread
    (its own GL context). Two scenes alternate: one is drawn while the next is built."""

    def __init__(self, model, width, height, quality, sink):
        super().__init__(name="derods-render", daemon=True)
        self.args = (model, width, height, quality)
        self.sink = sink
        self.work: queue.Queue = queue.Queue()
        self.free: queue.Queue = queue.Queue()
        for i in range(2):
            self.free.put(i)
        self.error: BaseException | None = None
        self.last: np.ndarray | None = None
        self.quality = None
        self.ready = threading.Event()

    def run(self):
        raster = None
        try:
            raster = Raster(*self.args)
            self.quality = raster.quality
            self.ready.set()
            while True:
                item = self.work.get()
                if item is None:
                    break
                index, scene = item
                try:
                    self.last = raster.draw(scene)
                finally:
                    self.free.put(index)
                self.sink(self.last)
        except BaseException as err:  # handed to the main thread
            self.error = err
            self.ready.set()
            self.free.put(-1)  # wake a waiting producer
        finally:
            if raster is not None:
                raster.close()

    def next_index(self) -> int:
        index = self.free.get()
        if self.error is not None:
            raise self.error
        return index

    def submit(self, index: int, scene) -> None:
        self.work.put((index, scene))

    def finish(self) -> None:
        self.work.put(None)
        self.join()
        if self.error is not None:
            raise self.error


def frame_plan(seconds: float, fps: float, dt: float) -> np.ndarray:
    """The steps of ``dt`` [s] between the frames of a video of exactly ``seconds`` of
    simulated time at ``fps``: frame 0 is the start, frame i the step nearest to i / fps
    (so frames sit within dt / 2 of their time when a frame is not a whole number of
    steps). Refuses (ValueError, with the fix) a time that is not a whole number of steps
    or of frames, and more frames than steps. Returns shape (n_frames - 1,), int."""
    for name, v, unit in (("seconds", seconds, "s"), ("fps", fps, "1/s"), ("dt", dt, "s")):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0 [{unit}], got {v!r}")
    steps = int(round(seconds / dt))
    if steps < 1 or abs(steps * dt - seconds) > 1e-6 * seconds:
        raise ValueError(f"{seconds:g} s is not a whole number of steps of dt = {dt:g} s; "
                         f"use seconds = {max(steps, 1) * dt:.6g} or a dt that divides it")
    intervals = int(round(seconds * fps))
    if intervals < 1 or abs(intervals - seconds * fps) > 1e-6 * max(1.0, seconds * fps):
        lo, hi = max(intervals, 1) / fps, (max(intervals, 1) + 1) / fps
        raise ValueError(f"{seconds:g} s at {fps:g} frames/s is {seconds * fps:.4g} frames, not a whole number; "
                         f"use seconds = {lo:.6g} or {hi:.6g}")
    if intervals > steps:
        raise ValueError(f"fps {fps:g} asks for more frames than steps (dt {dt:g} s): use fps <= {1 / dt:g} "
                         f"or dt <= {1 / fps:g} s")
    at = np.rint(np.arange(intervals + 1) * steps / intervals).astype(int)
    return np.diff(at)


def film(world, out, seconds: float, fps: float, width: int, height: int, camera=None, paint=None,
         before_step=None, progress: bool = True, label: str = "film", quality: str = "auto", after_frame=None,
         before_close=None, lines: bool = False) -> dict:
    """Step a :class:`derods.World` for exactly ``seconds`` of simulated time and write what
    ``camera`` sees to an MP4 at ``fps`` (frame 0 is the start; see :func:`frame_plan`),
    ``seconds * fps + 1`` frames.

    paint: optional scene callback (overlays). before_step: optional ``f(world)`` called
    before every step (to move clamps, set controls). after_frame, before_close: optional
    ``f(world)`` checks after every frame's steps and before the video is kept (raise to
    discard it). lines: draw the rods as lines (:func:`derods.viz.overlay.rod_lines`)
    instead of their flexes. Physics runs in this thread, drawing and encoding in another. Shows a progress bar. Returns {"frames", "last" (the last
    image, (height, width, 3) uint8), "quality"}; the video appears only when complete.
    """
    from tqdm import tqdm

    out = check_output_path(out, VIDEO_SUFFIXES, "video")
    between = frame_plan(seconds, fps, world.model.opt.timestep)
    check_frame_size(world.model, width, height)
    if lines:
        from .overlay import n_edges, rod_lines

        draw_lines = rod_lines(world)
        view = View(world.model, camera, n_scenes=2, max_geom=10000 + n_edges(world), draw_flexes=False)
        paint = draw_lines if paint is None else (lambda scene, first=paint: (draw_lines(scene), first(scene)))
    else:
        view = View(world.model, camera, n_scenes=2)
    with VideoWriter(out, (height, width), fps) as video:
        drawer = _Drawer(world.model, width, height, quality, video.add)
        drawer.start()
        try:
            drawer.ready.wait()
            index = drawer.next_index()
            drawer.submit(index, view.build(world.data, paint, index))
            for n_steps in tqdm(between, desc=label, unit="frame", disable=not progress, leave=False):
                if before_step is None:
                    world.step(int(n_steps))
                else:
                    for _ in range(n_steps):
                        before_step(world)
                        world.step()
                if after_frame is not None:
                    after_frame(world)
                index = drawer.next_index()
                drawer.submit(index, view.build(world.data, paint, index))
            if before_close is not None:
                before_close(world)
        except BaseException:
            drawer.work.put(None)
            drawer.join(timeout=10.0)
            raise
        drawer.finish()
    return {"frames": video.frames, "last": drawer.last, "quality": drawer.quality}
