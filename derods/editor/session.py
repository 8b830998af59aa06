"""An editing session: the curve a user shapes, the rod made from it, and its simulation.

:class:`Session` is the editor's logic with no user interface: every control of the
browser editor is one public method here (move a control point, set a join's
continuity, add or remove a segment, set the rod's settings, start, pause, step, reset,
pull a vertex), so tests drive it directly and the interface only wires widgets to it.
Two modes: editing (the curve, its samples, Bishop frames, curvature and torsion are
shown) and simulating (a real :class:`derods.World` in the chosen MuJoCo scene, built
from the curve when the user starts, thrown away on reset).
"""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
import time
from dataclasses import dataclass

import numpy as np

from .. import frames, reference, scenes, shapes
from ..material import Material
from ..rod import Rod
from ..sim.world import ContactParams, World
from ..twist import TwistBoundary
from ..viz.output import atomic_output
from .curve import Curve

ENDS = ("free", "pin", "clamp")
RESTS = ("straight", "curve")
#: The curve a session starts with: two C1 segments, a wave 0.5 m above the floor [m].
#: A mouse pull's spring: the rate [1/s] of a critically damped spring on the pulled
#: vertex's mass: 100 holds a 0.8 m rod's middle 2 cm below the mouse (dt 2e-3 to 1e-2, stable).
PULL_RATE = 100.0
DEFAULT_POINTS = [[-0.4, 0.0, 0.5], [-0.3, 0.15, 0.55], [-0.1, 0.15, 0.5], [0.0, 0.0, 0.5],
                  [0.1, -0.15, 0.5], [0.3, -0.15, 0.45], [0.4, 0.0, 0.5]]


@dataclass(frozen=True)
class Settings:
    """The rod made from the curve.

    n_edges: samples along the curve (edges). young, shear [Pa] (shear None: from
    Poisson's ratio 0.5), radius [m], density [kg/m^3]: the material; bending stiffness
    alpha = E pi r^4 / 4 [N m^2] and twisting beta = G pi r^4 / 2. rest: "straight" (the
    rod springs straight from the drawn shape) or "curve" (the drawn shape is its rest
    shape). start, end: "free", "pin" or "clamp". end_twist [rad]: imposed between two
    clamps. mass_damping [1/s]. dt [s]: the simulation's step.
    """

    n_edges: int = 40
    young: float = 2e6
    shear: float | None = None
    radius: float = 0.008
    density: float = 1100.0
    rest: str = "straight"
    start: str = "free"
    end: str = "free"
    end_twist: float = 0.0
    mass_damping: float = 0.5
    dt: float = 2e-3

    def __post_init__(self):
        if int(self.n_edges) != self.n_edges or not 2 <= self.n_edges <= 2000:
            raise ValueError(f"n_edges must be an integer in [2, 2000], got {self.n_edges!r}")
        for name in ("young", "radius", "density", "dt"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        if self.shear is not None and not (math.isfinite(self.shear) and self.shear > 0):
            raise ValueError(f"shear must be finite and > 0 [Pa] (or None), got {self.shear!r}")
        if self.rest not in RESTS:
            raise ValueError(f"rest must be one of {RESTS}, got {self.rest!r}")
        for name in ("start", "end"):
            if getattr(self, name) not in ENDS:
                raise ValueError(f"{name} must be one of {ENDS}, got {getattr(self, name)!r}")
        if not math.isfinite(self.end_twist):
            raise ValueError(f"end_twist must be finite [rad], got {self.end_twist!r}")
        if self.end_twist and not (self.start == self.end == "clamp"):
            raise ValueError("end_twist needs both ends clamped (start='clamp', end='clamp')")
        if not (math.isfinite(self.mass_damping) and self.mass_damping >= 0):
            raise ValueError(f"mass_damping must be finite and >= 0 [1/s], got {self.mass_damping!r}")

    @property
    def material(self) -> Material:
        return Material(young=self.young, shear=self.shear, radius=self.radius, density=self.density)


class Session:
    """The editor's state and actions. scene: a scene name or MJCF path for the
    simulation (its geometry is what the rod falls onto). curve, settings: the start.

    Attributes a drawing reads: ``curve``, ``settings``, ``world`` (None while editing),
    ``running``, ``sim_time`` [s], ``real_time_factor`` (simulated over wall time of the
    last :meth:`advance`).
    """

    def __init__(self, scene: str | pathlib.Path = "floor", curve: Curve | None = None,
                 settings: Settings | None = None):
        self.scene = str(scenes.path(scene))
        self.curve = curve or Curve.make(DEFAULT_POINTS)
        self.settings = settings or Settings()
        self.world: World | None = None
        self.running = False
        self.real_time_factor = 0.0
        self.michell: float | None = None  # the ring's twist over the critical one, in the Michell preset
        self._pull: tuple[int, np.ndarray] | None = None

    # -- editing ---------------------------------------------------------------------------
    def move_point(self, index: int, position) -> None:
        """Drag control point ``index`` to ``position`` [m] (C1 joins stay smooth)."""
        self._editing("move a control point")
        self.curve = self.curve.moved(index, position)

    def set_join(self, join: int, continuity: str) -> None:
        """Inner join ``join`` (1 .. segments - 1) made "C0" or "C1"."""
        self._editing("change a join")
        self.curve = self.curve.with_join(join, continuity)

    def add_segment(self) -> None:
        self._editing("add a segment")
        self.curve = self.curve.with_segment_added()

    def remove_segment(self, segment: int) -> None:
        self._editing("remove a segment")
        self.curve = self.curve.with_segment_removed(segment)

    def set_settings(self, **changes) -> None:
        """Change the rod's settings (see :class:`Settings`); checked before they apply.
        A running simulation keeps the rod it was built with: they apply from the next
        start after a reset."""
        self.settings = dataclasses.replace(self.settings, **changes)

    def _editing(self, what: str) -> None:
        if self.world is not None:
            raise RuntimeError(f"cannot {what} while the rod is simulated; reset first")

    # -- what editing shows -----------------------------------------------------------------
    def samples(self) -> np.ndarray:
        """The rod's vertices [m], (n_edges + 1, 3): the curve at equal arc length."""
        if self.michell is not None:
            return self._ring_vertices()
        return self.curve.sample(self.settings.n_edges)

    def bishop_frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, u, v) per edge of the samples, each (n_edges, 3): tangent, and the
        twist-free normal and binormal transported along the curve from the first edge."""
        x = self.samples()
        closed = self.michell is not None
        t = frames.tangents(x, closed)
        u = frames.bishop_frames(x, closed)
        return t, u, np.cross(t, u)

    def curvature_torsion(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(s, kappa, tau): arc length [m] of each sample and the curve's curvature and
        torsion there [1/m] (exact, from the Bezier's derivatives)."""
        s = np.linspace(0.0, self.curve.length, self.settings.n_edges + 1)
        kappa, tau = self.curve.curvature_torsion(s)
        return s, kappa, tau

    # -- simulation -------------------------------------------------------------------------
    def build(self) -> World:
        """The World of the curve's rod in the scene (not yet stepped)."""
        st = self.settings
        if self.michell is not None:
            return self._ring_world()
        world = World(self.scene, dt=st.dt, mass_damping=st.mass_damping, contact=ContactParams(friction=0.8))
        twist = {"boundary": TwistBoundary("clamped", 0.0, st.end_twist)} if st.start == st.end == "clamp" else {}
        rod = Rod(self.samples(), st.material, natural_curvature=st.rest == "curve", **twist)
        world.add_rod(rod, "rod", start=st.start, end=st.end)
        world.compile()
        return world

    def start(self) -> None:
        """Run (building the world from the curve if there is none)."""
        if self.world is None:
            self.world = self.build()
        self.running = True

    def pause(self) -> None:
        self.running = False

    def step(self, n_steps: int = 1) -> None:
        """Advance the simulation by n steps (building it if needed), running or paused."""
        if self.world is None:
            self.world = self.build()
        if self._pull is None:
            self.world.step(n_steps)
        else:
            self._step_pulled(n_steps)

    def advance(self, wall_seconds: float) -> int:
        """While running: the steps that cover ``wall_seconds`` of simulated time (rounded
        down; none if less than a step), timed; returns the steps made."""
        if not self.running or self.world is None:
            return 0
        n = int(wall_seconds / self.world.model.opt.timestep + 1e-9)
        if n == 0:
            return 0
        t0 = time.perf_counter()
        self.step(n)
        wall = time.perf_counter() - t0
        self.real_time_factor = n * self.world.model.opt.timestep / max(wall, 1e-9)
        return n

    def reset(self) -> None:
        """Stop and go back to the edited curve (the world is dropped)."""
        self.world = None
        self.running = False
        self.real_time_factor = 0.0
        self._pull = None

    @property
    def sim_time(self) -> float:
        return 0.0 if self.world is None else self.world.time

    def positions(self) -> np.ndarray:
        """The rod's vertices now [m]: simulated if a world runs, else the samples."""
        return self.samples() if self.world is None else self.world.positions("rod")

    def pull(self, vertex: int, target) -> None:
        """Pull vertex ``vertex`` towards the point ``target`` [m] (world frame), as a mouse
        drag does, until :meth:`release`: a critically damped spring of PULL_RATE [1/s] on
        the vertex's own mass, recomputed every step (a force held over many steps would
        throw the vertex past its target)."""
        if self.world is None:
            raise RuntimeError("start the simulation before pulling the rod")
        target = np.asarray(target, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError(f"target must be 3 finite coordinates [m], got {target!r}")
        self.world.vertex_body("rod", vertex)  # checks the index
        self._pull = (int(vertex), target)

    def release(self) -> None:
        if self.world is not None and self._pull is not None:
            self.world.data.xfrc_applied[self.world.vertex_body("rod", self._pull[0]), :3] = 0.0
        self._pull = None

    def _step_pulled(self, n_steps: int) -> None:
        """n steps with the pull's spring force recomputed before each."""
        v, target = self._pull
        w = self.world
        body = w.vertex_body("rod", v)
        mass = float(w.model.body_mass[body])
        for _ in range(n_steps):
            x, vel = w.positions("rod")[v], w.velocities("rod")[v]
            w.data.xfrc_applied[body, :3] = mass * (PULL_RATE**2 * (target - x) - 2.0 * PULL_RATE * vel)
            w.step()

    # -- Michell's twisted ring -------------------------------------------------------------
    @property
    def critical_twist(self) -> float:
        """Michell's critical total twist of a naturally straight ring [rad]:
        2 pi sqrt(3) alpha / beta."""
        mat = self.settings.material
        return reference.michell_critical_twist(mat.alpha, mat.beta)

    def michell_preset(self, twist_ratio: float = 1.2) -> None:
        """Switch to a closed ring (circumference: the curve's length) twisted to
        ``twist_ratio`` times the critical twist, no gravity; :meth:`edit_curve` goes back."""
        if not (math.isfinite(twist_ratio) and twist_ratio >= 0):
            raise ValueError(f"twist_ratio must be finite and >= 0, got {twist_ratio!r}")
        self.reset()
        self.michell = float(twist_ratio)

    def edit_curve(self) -> None:
        self.reset()
        self.michell = None

    def _ring_vertices(self) -> np.ndarray:
        radius = self.curve.length / (2.0 * math.pi)
        return shapes.circle(radius, self.settings.n_edges, center=(0.0, 0.0, 0.5))

    def _ring_world(self) -> World:
        st = self.settings
        x = self._ring_vertices()
        world = World(dt=st.dt, gravity=(0.0, 0.0, 0.0))
        rod = Rod(x, st.material, closed=True, natural_curvature=False,
                  boundary=TwistBoundary("ring", total_twist=self.michell * self.critical_twist))
        world.add_rod(rod, "rod")
        # a whisper of modes 2 and 3 out of the plane, for the instability to grow from
        phi = 2.0 * math.pi * np.arange(len(x)) / len(x)
        xp = x.copy()
        xp[:, 2] += 1e-3 * self.curve.length / (2 * math.pi) * (np.sin(2 * phi) + 0.1 * np.cos(3 * phi))
        world.set_positions("rod", xp)
        return world

    def export(self, path, seconds: float = 5.0, width: int = 960, height: int = 540) -> dict:
        """Film the rod for ``seconds`` [s] from where it is (the edited curve if no world
        runs) to an MP4 at ``path``, through :func:`derods.viz.filming.film` (headless,
        written atomically); the session's own world is not advanced."""
        from ..viz import filming, render

        world = self.build()
        if self.world is not None:  # start the film from the running rod's state
            world.set_positions("rod", self.world.positions("rod"))
            world.set_velocities("rod", self.world.velocities("rod"))
        render.check_frame_size(world.model, width, height)
        names = {world.model.camera(i).name for i in range(world.model.ncam)}
        return filming.film(world, path, seconds, 30.0, width, height, "main" if "main" in names else None,
                            progress=False)

    # -- files ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"format": "derods-edit/1", "curve": self.curve.to_dict(),
                "settings": dataclasses.asdict(self.settings), "michell": self.michell}

    def save(self, path) -> pathlib.Path:
        """Write the edited rod (curve, settings, preset) as JSON, atomically."""
        path = pathlib.Path(path)
        with atomic_output(path) as tmp:
            pathlib.Path(tmp).write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        return path

    def load(self, path) -> None:
        """Read a file :meth:`save` wrote (back to editing)."""
        path = pathlib.Path(path)
        try:
            d = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise ValueError(f"cannot read {str(path)!r}: {err}") from None
        if not isinstance(d, dict) or d.get("format") != "derods-edit/1":
            raise ValueError(f"{str(path)!r} is not a derods edit file (format 'derods-edit/1')")
        curve = Curve.from_dict(d["curve"])
        settings = Settings(**d.get("settings", {}))
        self.reset()
        self.curve, self.settings, self.michell = curve, settings, d.get("michell")
