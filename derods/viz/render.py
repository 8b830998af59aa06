"""Off-screen rendering of MuJoCo scenes to RGB images, headless by default.

MuJoCo renders through OpenGL. derods makes its own GL context when a renderer
is first made: the backend the user chose (``MUJOCO_GL``), else EGL (Mesa on the
CPU) on a Linux machine without a display, else MuJoCo's default. Importing
derods or MuJoCo sets nothing.

Quality: on software GL (Mesa's llvmpipe) a 960x540 frame with a 4096 shadow
map, 4x MSAA and floor reflections costs ~250 ms of CPU; ``quality="fast"``
(shadow map 1024, no MSAA, no reflections) ~50 ms and looks nearly the same
(docs/render_quality.png). ``"auto"`` (the default) picks "fast" on software GL
and the scene's own settings ("full") on a GPU.

Images are written by :mod:`derods.viz.output`; videos of a running world are made by
:func:`derods.viz.filming.film`.
"""

from __future__ import annotations

import os
import sys

import numpy as np

#: Render settings by quality: (shadow map size [pixels], MSAA samples, floor reflections).
QUALITIES = {"fast": (1024, 0, False), "full": None}
#: GL renderers that run on the CPU, where "auto" picks "fast".
SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast", "swiftshader")


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

