"""``derods hair``: a head of curled strands on a moving head, filmed headlessly.

:class:`HairParams` holds what the command line sets; :func:`run` builds the world
(:func:`derods.hair.build`), drives the head (:class:`derods.hair.Motion`), checks the
hair while it is filmed (roots on the scalp, strands out of the skull and unstretched)
and writes the video, the strands drawn as lines (:func:`derods.viz.overlay.rod_lines`:
drawing 1000 flexes costs ~5 s a frame on software GL, lines ~0.4 s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco

from .. import hair as hair_mod
from ..sim.divergence import DivergenceError
from ..viz import filming, output


@dataclass(frozen=True)
class HairParams:
    """A hair video. hair: the strands (:class:`derods.hair.Hair`); motion: head motion
    name (see :data:`derods.hair.MOTIONS`); seconds [s] simulated, dt [s] step; fps,
    width, height [pixels] of the video; camera: a camera of the head scene;
    strand_contact: strands touch one another (off: they pass through)."""

    hair: hair_mod.Hair = field(default_factory=hair_mod.Hair)
    motion: str = "shake"
    seconds: float = 3.0
    dt: float = 1e-2
    fps: float = 25.0
    width: int = 960
    height: int = 540
    camera: str = "main"
    strand_contact: bool = False

    def __post_init__(self):
        hair_mod.Motion(self.motion)  # refuses an unknown motion


#: Checked on every frame: roots on the scalp [m] and strands out of the skull [m].
ROOT_DRIFT_MAX = 1e-6


def check_hair(world, hair: hair_mod.Hair) -> float:
    """Raise DivergenceError if a root left its scalp site or a strand went a radius deep
    into the skull (the video would show it); returns that depth [m]."""
    drift = hair_mod.root_drift(world, hair)
    if drift > ROOT_DRIFT_MAX:
        raise DivergenceError(f"a strand's root left the scalp by {drift:.3g} m at t = {world.time:.3g} s")
    depth = hair_mod.penetration(world)
    if depth > hair.radius:
        raise DivergenceError(f"a strand went {depth * 1e3:.2f} mm into the skull (more than its radius, "
                              f"{hair.radius * 1e3:g} mm) at t = {world.time:.3g} s; try a smaller dt")
    return depth


def run(p: HairParams, out, progress: bool = True, still=None, quality: str = "auto") -> dict:
    """Simulate ``p`` and write an MP4 to ``out`` (and the last frame to the PNG ``still``);
    returns a summary dict: out, frames, sim_s, steps, strands, vertices, build_s,
    max_penetration [m], max_strain."""
    import time

    out, still = output.check_outputs(out, still)
    filming.frame_plan(p.seconds, p.fps, p.dt)
    t0 = time.perf_counter()
    world = hair_mod.build(p.hair, dt=p.dt, strand_contact=p.strand_contact)
    world.compile()
    build_s = time.perf_counter() - t0
    if mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_CAMERA, p.camera) < 0:
        raise ValueError(f"unknown camera {p.camera!r}; the head scene has 'main'")
    worst = {"penetration": 0.0, "strain": 0.0}

    def after_frame(w):
        worst["penetration"] = max(worst["penetration"], check_hair(w, p.hair))
        worst["strain"] = max(worst["strain"], hair_mod.max_strain(w))

    result = filming.film(world, out, p.seconds, p.fps, p.width, p.height, p.camera,
                          before_step=hair_mod.drive(world, hair_mod.Motion(p.motion)), progress=progress,
                          label=f"hair {p.motion}", quality=quality, after_frame=after_frame, lines=True)
    if still is not None:
        output.write_image(still, result["last"])
    return {"out": str(out), "frames": result["frames"], "sim_s": world.time, "steps": world.n_steps,
            "strands": p.hair.strands, "vertices": p.hair.vertices, "build_s": build_s,
            "max_penetration": worst["penetration"], "max_strain": worst["strain"]}
