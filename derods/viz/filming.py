"""Filming a world: step a :class:`derods.World` and write what a camera sees to an MP4.

:func:`film` steps the world in the calling thread while a second thread draws the frames
(:mod:`derods.viz.render`) and pipes them to the video (:mod:`derods.viz.output`):
MuJoCo's step and its renderer both release the GIL. :func:`frame_plan` says which steps
the frames sit on, and refuses times, rates and steps that do not make whole frames.
"""

from __future__ import annotations

import queue
import threading

import numpy as np

from .output import VIDEO_SUFFIXES, VideoWriter, check_output_path
from .render import Raster, View, check_frame_size


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


def step_or_film(world, seconds: float, before_step=None, out=None, size=(1280, 720), camera="main",
                 fps: float = 30.0) -> None:
    """Step ``world`` for ``seconds`` [s] of simulated time, calling ``before_step(world)``
    before each step (a controller); with ``out`` (a path), film it there as :func:`film`
    does (``size`` (width, height) [px], ``camera``, ``fps``), without a progress bar."""
    if out is None:
        while world.time < seconds - 1e-9:
            if before_step is not None:
                before_step(world)
            world.step()
        return
    film(world, out, seconds, fps, size[0], size[1], camera, before_step=before_step, progress=False)
