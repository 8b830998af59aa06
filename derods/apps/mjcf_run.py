"""``derods run MODEL.xml`` and ``derods view MODEL.xml``: a MuJoCo model with rods declared in
it (cable composites of MuJoCo 3.x, or 1D flexcomps with ``--rods-from flexcomp``; see
:mod:`derods.io.mjcf_load`), filmed headlessly to an MP4 or opened in MuJoCo's viewer.

``--ctrl NAME=VALUE`` sets an actuator's control (held for the whole run); a model's
keyframe named by ``--key`` sets time, controls and mocap poses first. Bad input is one
line and exit code 2 (the command line's rule).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np


def register(sub, view_parser: argparse.ArgumentParser) -> None:
    """Add ``run`` to the command line's subparsers, and a MODEL argument to ``view`` (which
    keeps its drop scene when none is given)."""
    r = sub.add_parser("run", help="film a MuJoCo model with rods declared in it (cable composites) to an MP4")
    r.add_argument("model", help="MJCF file (MuJoCo 3.x cable composites are read as derods rods)")
    r.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    r.add_argument("--dt", type=float, default=None, help="time step [s] (default: the model's)")
    r.add_argument("--fps", type=float, default=25.0, help="frames per second (default 25)")
    r.add_argument("--width", type=int, default=960, help="frame width [px] (default 960)")
    r.add_argument("--height", type=int, default=540, help="frame height [px] (default 540)")
    r.add_argument("--camera", default=None, help="camera name (default: the model's 'main', else one added)")
    r.add_argument("--out", default=None, help="video file (default: MODEL's name with .mp4, here)")
    r.add_argument("--ctrl", action="append", default=[], metavar="NAME=VALUE",
                   help="an actuator's control, held for the run (repeatable)")
    r.add_argument("--key", default=None, help="a keyframe of the model to start from (its time, ctrl, mocap)")
    r.add_argument("--rods-from", choices=["composite", "flexcomp"], default="composite",
                   help="composite (default): cable composites become rods; flexcomp: 1D flexcomps too")
    r.add_argument("--quality", choices=["auto", "fast", "full"], default="auto")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=run)
    view_parser.add_argument("model", nargs="?", default=None,
                             help="an MJCF file with rods declared in it (default: the drop scene of --scene)")
    view_parser.add_argument("--ctrl", action="append", default=[], metavar="NAME=VALUE",
                             help="with MODEL: an actuator's control at the start (repeatable)")
    view_parser.add_argument("--rods-from", choices=["composite", "flexcomp"], default="composite")
    drop_view = view_parser.get_default("func")
    view_parser.set_defaults(func=lambda args: view(args) if args.model else drop_view(args))


def parse_ctrl(items: list[str], model) -> dict[int, float]:
    """``NAME=VALUE`` strings as {actuator id: value}; refuses (ValueError, one line) an unknown
    actuator or a value that is not a number, naming the actuators there are."""
    import mujoco

    out = {}
    names = [model.actuator(i).name for i in range(model.nu)]
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--ctrl {item!r} must be NAME=VALUE, e.g. --ctrl {names[0] if names else 'motor'}=0.5")
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if i < 0:
            raise ValueError(f"--ctrl {item!r}: the model has no actuator {name!r}; its actuators: {names or 'none'}")
        try:
            out[i] = float(value)
        except ValueError:
            raise ValueError(f"--ctrl {item!r}: {value!r} is not a number") from None
        if not np.isfinite(out[i]):
            raise ValueError(f"--ctrl {item!r}: the value must be finite")
    return out


def build(model_path: str, dt: float | None, rods_from: str, width: int = 0, height: int = 0, camera=None,
          notes=None):
    """The :class:`derods.World` of a model file with rods, ready to film at width x height
    (an offscreen buffer, a light and a camera "main" added where the model lacks them,
    said through ``notes``)."""
    from derods import World
    from derods.apps.drop import prepare_for_video

    path = pathlib.Path(model_path)
    if not path.is_file():
        raise ValueError(f"model file {model_path!r} does not exist")
    import warnings

    from derods.validation import SceneWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SceneWarning)
        world = World(str(path), dt=dt, rods_from=rods_from)
    for w in caught:
        if issubclass(w.category, SceneWarning):
            (notes or (lambda t: None))(str(w.message))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if not world.rods:
        raise ValueError(f"{model_path}: the model declares no rods (no <composite type=\"cable\">"
                         + ("" if rods_from == "flexcomp" else "; for 1D flexcomps pass --rods-from flexcomp") + ")")
    if width and height:
        x = np.concatenate([e.x0 for e in world._entries])
        for text in prepare_for_video(world.spec, width, height, x, False):
            (notes or (lambda t: None))(text)
        if camera is None and not any(c.name == "main" for c in world.spec.cameras):
            pos = add_camera(world.spec, x)
            (notes or (lambda t: None))(f"the model has no camera 'main'; added one looking at its rods from "
                                        f"{np.round(pos, 2).tolist()} m")
    world.compile()
    return world


def add_camera(spec, x: np.ndarray) -> np.ndarray:
    """Add a camera "main" to ``spec`` that frames points x [m], shape (n, 3), and the ground
    below them (z = 0) from the front (-y) and 25 degrees above, at a distance that fits their
    extent; returns its position."""
    import math

    lo, hi = x.min(axis=0), x.max(axis=0)
    lo[2] = min(lo[2], 0.0)
    target = 0.5 * (lo + hi)
    dist = 1.6 * float(np.linalg.norm(hi - lo)) + 0.2
    elev = math.radians(25.0)
    pos = target + dist * np.array([0.0, -math.cos(elev), math.sin(elev)])
    fwd = (target - pos) / np.linalg.norm(target - pos)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    spec.worldbody.add_camera(name="main", pos=pos, xyaxes=np.concatenate([right, np.cross(right, fwd)]))
    return pos


def _start(world, args) -> None:
    """Apply --key and --ctrl."""
    import mujoco

    m, d = world.model, world.data
    if getattr(args, "key", None):
        k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, args.key)
        if k < 0:
            names = [m.key(i).name for i in range(m.nkey)]
            raise ValueError(f"--key {args.key!r}: the model has no such keyframe; its keyframes: {names or 'none'}")
        d.ctrl[:] = m.key_ctrl[k]
        d.mocap_pos[:] = m.key_mpos[k].reshape(-1, 3)
        d.mocap_quat[:] = m.key_mquat[k].reshape(-1, 4)
    for i, v in parse_ctrl(args.ctrl, m).items():
        d.ctrl[i] = v


def run(args: argparse.Namespace) -> int:
    """``derods run``: film the model headlessly."""
    from derods.sim import warmup
    from derods.viz import filming, output

    out = args.out or pathlib.Path(args.model).with_suffix(".mp4").name
    output.check_outputs(out, None)
    notes = (lambda text: print(f"derods run: note: {text}", file=sys.stderr)) if not args.quiet else None
    world = build(args.model, args.dt, args.rods_from, args.width, args.height, args.camera, notes)
    filming.frame_plan(args.seconds, args.fps, world.model.opt.timestep)
    _start(world, args)
    warmup.prepare()
    camera = args.camera or "main"
    result = filming.film(world, out, args.seconds, args.fps, args.width, args.height, camera,
                         paint=stress_painter(world), progress=not args.quiet, label="run", quality=args.quality)
    print(f"wrote {out}: {result['frames']} frames, {world.time:.4g} s simulated ({world.n_steps} steps, "
          f"{world.mode}), rods {', '.join(world.rod_names)}")
    return 0


def stress_painter(world):
    """A scene callback that draws each rod whose cable plugin set ``vmax`` as a tube coloured
    by its elastic moment on MuJoCo's jet scale up to vmax [N m]
    (:func:`derods.viz.overlay.internal_moment`), its flex hidden; None if no rod has one."""
    from derods.viz import overlay

    scale = {i: d.vmax for i, d in enumerate(world._declared) if d.vmax}
    if not scale:
        return None
    import mujoco

    m = world.model
    for i in scale:  # the coloured tube replaces the flex
        m.flex_rgba[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, world.rod_names[i]), 3] = 0.0

    def paint(scene):
        for i, vmax in scale.items():
            rod, x = world.rods[i], world.positions(i)
            moment = overlay.internal_moment(rod, x, world.rod_state(i))
            overlay.add_tube(scene, x, rod.material.radius, overlay.jet_colours(moment, vmax), closed=rod.closed)

    return paint


def view(args: argparse.Namespace) -> int:
    """``derods view MODEL.xml``: the model in MuJoCo's viewer, stepped by derods in real time."""
    from derods.apps.commands import require_display, show

    require_display("derods run")
    world = build(args.model, None, args.rods_from)
    _start(world, args)
    show(world)
    return 0
