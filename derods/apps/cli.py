"""The ``derods`` command line (``python -m derods``).

Commands:
  drop    drop rods onto a rigid scene and write an MP4 (headless).
  hair    a thousand curled strands on a shaking, nodding or turning head, as an MP4.
  frames  draw a Bezier rod with its Bishop frames to a PNG (C0 or C1 joins).
  michell draw twisted rings below and above Michell's critical twist to a PNG.
  view    open a scene with rods in MuJoCo's interactive viewer (needs a display).
  run     film a MuJoCo model with rods declared in it (cable composites) to an MP4 (headless).
  compare sweep benchmark cases over backends and resolutions; write a report.
  demo    build rods from the paper's test cases and print their frames and energies.
  bench   run a benchmark case (cantilever, frequency, drop, michell, circle, twist, stability, extreme,
          oscillation, hair) and print records.
"""

from __future__ import annotations

import argparse
import signal
import sys

import numpy as np

#: Control points [m] of the demo's two-segment cubic Bezier curve.
DEMO_CONTROL_POINTS = np.array([
    [0.0, 0.0, 0.0], [0.3, 0.4, 0.0], [0.6, 0.5, 0.2], [1.0, 0.3, 0.2],
    [1.2, -0.3, 0.5], [1.5, 0.0, 0.0], [1.8, 0.4, 0.1],
])


def _positive_int(text: str) -> int:
    v = int(text)
    if v < 2:
        raise argparse.ArgumentTypeError(f"must be an integer >= 2, got {text}")
    return v


def demo(args: argparse.Namespace) -> int:
    """Bezier rods with C0 and C1 joins, a clamped twisted rod and a twisted ring."""
    import derods
    from derods import frames, geometry, shapes
    from derods.twist import TwistBoundary

    n = args.n_edges
    mat = derods.Material(young=args.young, radius=args.radius, density=args.density)
    print(f"derods {derods.__version__}: material E = {mat.young:.3g} Pa, r = {mat.radius:g} m, "
          f"alpha = EI = {mat.alpha:.4g} N m^2, beta = GJ = {mat.beta:.4g} N m^2")

    print(f"\n1. Bishop frames on a two-segment cubic Bezier curve, {n} edges")
    for cont in ("C0", "C1"):
        p = shapes.bezier_control_points(DEMO_CONTROL_POINTS, cont)
        x = shapes.bezier(DEMO_CONTROL_POINTS, n, cont)
        u = frames.bishop_frames(x, False)
        k = int(np.argmin(np.linalg.norm(x - shapes.bezier_eval(p, 1.0), axis=1)))
        angles = np.degrees(geometry.turning_angles(x, False))
        rod = derods.Rod(x, mat)
        print(f"   {cont}: largest turning angle {angles.max():6.2f} deg "
              f"(at the join, vertex {k}: {angles[max(k - 1, 0)]:6.2f} deg); "
              f"Bishop u at the ends {np.round(u[0], 3)} -> {np.round(u[-1], 3)}; "
              f"terms {rod.active_terms}")

    print("\n2. A straight rod, both ends clamped, one end turned by 2 pi")
    rod = derods.Rod(shapes.straight(1.0, n), mat, boundary=TwistBoundary("clamped", 0.0, 2 * np.pi))
    state = rod.advance(rod.rest_state(), rod.rest_x)
    l_eff = 1.0 - 1.0 / n
    print(f"   twist energy {rod.energy(state):.6g} J; beta Theta^2 / (2 L') = "
          f"{mat.beta * (2 * np.pi) ** 2 / (2 * l_eff):.6g} J (L' = {l_eff:g} m between the clamped edges)")

    print("\n3. A naturally straight ring twisted by Theta (Michell's test case)")
    theta_c = 2 * np.pi * np.sqrt(3) * mat.alpha / mat.beta
    ring = derods.Rod(shapes.circle(0.25, n), mat, closed=True, natural_curvature=False,
                      boundary=TwistBoundary("ring", total_twist=0.5 * theta_c))
    rs = ring.advance(ring.rest_state(), ring.rest_x)
    bend = ring.derivatives(rs, 0, terms=("bend_isotropic",)).energy
    tw = ring.derivatives(rs, 0, terms=("twist",)).energy
    print(f"   critical twist 2 pi sqrt(3) alpha / beta = {theta_c:.4f} rad; at Theta = Theta_c / 2: "
          f"bending {bend:.6g} J (pi alpha / R = {np.pi * mat.alpha / 0.25:.6g}), twist {tw:.6g} J")
    return 0


def _before_filming(out, still, params) -> None:
    """Refuse what can be refused (the output paths; seconds, fps and dt that do not make
    whole frames) before the compiled kernels are prepared, then prepare them."""
    from derods.sim import warmup
    from derods.viz import render

    render.check_outputs(out, still)
    render.frame_plan(params.seconds, params.fps, params.dt)
    warmup.prepare()


def drop(args: argparse.Namespace) -> int:
    """``derods drop``: see :mod:`derods.apps.drop`."""
    if not args.quiet:
        print(f"derods drop: {args.rods} {args.shape} rods x {args.n_edges} edges onto {args.scene}, "
              f"{args.seconds:g} s at dt {args.dt:g} s, filmed at {args.fps:g} frames/s -> {args.out}",
              file=sys.stderr, flush=True)
    import derods
    from derods.apps import drop as drop_mod
    from derods.viz import figures

    mat = derods.Material(young=args.young, radius=args.radius, density=args.density)
    control = None if args.control is None else figures.parse_points(args.control)
    params = drop_mod.DropParams(
        scene=args.scene, rods=args.rods, shape=args.shape, n_edges=args.n_edges, length=args.length,
        seconds=args.seconds, dt=args.dt, fps=args.fps, width=args.width, height=args.height,
        camera=args.camera, material=mat, seed=args.seed, overlay=args.overlay, control=control, mode=args.mode)
    _before_filming(args.out, args.still, params)
    summary = drop_mod.drop(params, args.out, progress=not args.quiet, still=args.still, quality=args.quality,
                            notes=lambda text: print(f"derods drop: note: {text}", file=sys.stderr))
    print(f"wrote {summary['out']}: {summary['frames']} frames, {summary['sim_s']:.4g} s simulated "
          f"({summary['steps']} steps, {summary['mode']}, {summary['quality']} rendering), "
          f"rods {', '.join(summary['rods'])}" + (f"; still {args.still}" if args.still else ""))
    return 0


def hair(args: argparse.Namespace) -> int:
    """``derods hair``: see :mod:`derods.apps.hair`."""
    if not args.quiet:
        print(f"derods hair: {args.strands} strands x {args.vertices} vertices on a head ({args.motion}), "
              f"{args.seconds:g} s at dt {args.dt:g} s, filmed at {args.fps:g} frames/s -> {args.out}",
              file=sys.stderr, flush=True)
    from derods import hair as hair_mod
    from derods.apps import hair as app

    params = app.HairParams(hair=hair_mod.Hair(strands=args.strands, vertices=args.vertices, seed=args.seed),
                            motion=args.motion, seconds=args.seconds, dt=args.dt, fps=args.fps, width=args.width,
                            height=args.height, strand_contact=args.strand_contact)
    _before_filming(args.out, args.still, params)
    s = app.run(params, args.out, progress=not args.quiet, still=args.still, quality=args.quality)
    print(f"wrote {s['out']}: {s['frames']} frames, {s['sim_s']:.4g} s simulated ({s['steps']} steps), "
          f"{s['strands']} strands x {s['vertices']} vertices built in {s['build_s']:.1f} s; deepest strand in "
          f"the skull {s['max_penetration'] * 1e3:.2f} mm, largest strain {s['max_strain']:.1e}"
          + (f"; still {args.still}" if args.still else ""))
    return 0


def edit(args: argparse.Namespace) -> int:
    """``derods edit``: the rod editor in a browser (derods.editor.app)."""
    try:
        import viser  # noqa: F401
    except ImportError:
        raise ValueError("derods edit needs the browser editor's extra: pip install 'derods[ui]' "
                         "(make demo and make test install it)") from None
    from derods import scenes
    from derods.editor import app

    scenes.path(args.scene)  # an unknown scene is an error before a server starts
    if not 0 <= args.port <= 65535:
        raise ValueError(f"port must be in 0..65535, got {args.port}")
    app.serve(args.scene, host=args.host, port=args.port)
    return 0


def view(args: argparse.Namespace) -> int:
    """``derods view``: the drop scene in MuJoCo's viewer; drag a rod with the mouse
    (double-click it, then Ctrl + right-drag) and the pull enters the implicit step."""
    import os
    import time

    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise ValueError("derods view needs a display and none is set (DISPLAY); run it on a desktop, "
                         "or write a video with 'derods drop'")
    import mujoco.viewer

    from derods.apps import drop as drop_mod

    params = drop_mod.DropParams(scene=args.scene, rods=args.rods, shape=args.shape, n_edges=args.n_edges)
    world = drop_mod.build_world(params)
    h = world.model.opt.timestep
    with mujoco.viewer.launch_passive(world.model, world.data) as viewer:
        while viewer.is_running():
            start = time.perf_counter()
            world.step(max(1, int(round(1 / (60 * h)))))
            viewer.sync()
            time.sleep(max(0.0, 1 / 60 - (time.perf_counter() - start)))
    return 0


def frames_cmd(args: argparse.Namespace) -> int:
    """``derods frames``: see :func:`derods.viz.figures.bezier_frames`."""
    from derods.viz import figures

    points = figures.BEZIER_DEMO if args.control is None else figures.parse_points(args.control)
    info = figures.bezier_frames(args.out, points, args.continuity, args.n_edges, args.width, args.height)
    print(f"wrote {info['out']}: {args.continuity} joins, {args.n_edges} edges, "
          f"largest turning angle {info['max_turn_deg']:.1f} deg")
    return 0


def michell_cmd(args: argparse.Namespace) -> int:
    """``derods michell``: see :func:`derods.viz.figures.michell_pair`."""
    from derods.viz import figures

    info = figures.michell_pair(args.out, args.n_edges, args.below, args.above, args.seconds,
                                args.width, args.height)
    bend = ", ".join(f"{b * 1000:.2f} mm" for b in info["out_of_plane"])
    print(f"wrote {info['out']}: Theta_c = {info['theta_c']:.3f} rad; out of plane after "
          f"{args.seconds:g} s: {bend}")
    return 0


def compare_cmd(args: argparse.Namespace) -> int:
    """``derods compare``: see :mod:`derods.bench.sweep` and :mod:`derods.bench.report`."""
    import concurrent.futures
    import pathlib

    from derods.bench import report, sweep

    results = pathlib.Path(args.results)
    jobs = []
    if args.full:
        jobs = sweep.full_plan(tuple(args.backends.split(",")))
    elif not args.report_only:
        jobs = sweep.plan(args.cases.split(","), args.backends.split(","),
                            [int(v) for v in args.n_edges.split(",")], [float(v) for v in args.dt.split(",")],
                            tuple(args.modes.split(",")), young=args.young)
    if jobs and args.workers > 1:
        with concurrent.futures.ProcessPoolExecutor(args.workers) as ex:
            sweep.sweep(jobs, results, ex)
    elif jobs:
        sweep.sweep(jobs, results)
    path = report.report(results, args.report_dir, command="python -m derods " + " ".join(sys.argv[1:]))
    print(f"wrote {path}")
    return 0


def bench(args: argparse.Namespace) -> int:
    """``derods bench CASE``: see :mod:`derods.bench.cases`."""
    from derods import bench as bench_mod

    if args.case == "hair":
        from derods.bench import hair as hair_bench

        given = {k: getattr(args, k) for k in ("strands", "vertices", "dt", "motion", "seconds", "backend")
                 if getattr(args, k) is not None}
        given["strand_contact"] = args.strand_contact
        return hair_bench.main(hair_bench.HairCase(**given), args.json)
    for name in ("strands", "vertices", "motion", "seconds"):
        if getattr(args, name) is not None:
            raise ValueError(f"--{name} is an option of the hair case only")
    if args.strand_contact:
        raise ValueError("--strand-contact is an option of the hair case only")
    return bench_mod.main(args.case, bench_mod.params_from_args(args), args.json)


def _picture_args(parser: argparse.ArgumentParser, width: int, height: int, out: str) -> None:
    """The --width, --height and --out options shared by the picture commands."""
    parser.add_argument("--width", type=int, default=width, help=f"image width [pixels] (default {width})")
    parser.add_argument("--height", type=int, default=height, help=f"image height [pixels] (default {height})")
    parser.add_argument("--out", default=out, help=f"output PNG (default {out})")


def main(argv: list[str] | None = None) -> int:
    from derods.sim.world import MODES

    parser = argparse.ArgumentParser(prog="derods", description="Discrete Elastic Rods on MuJoCo")
    sub = parser.add_subparsers(dest="command", required=True)
    d = sub.add_parser("drop", help="drop rods onto a rigid scene and write an MP4 (headless)")
    d.add_argument("--scene", default="box",
                   help="floor, box, table_edge, stairs, pegs, halfpipe, rail, or an MJCF path (default box)")
    d.add_argument("--rods", type=int, default=3, help="number of rods (default 3)")
    d.add_argument("--shape", choices=["straight", "helix", "bezier", "ring"], default="straight",
                   help="rod shape (default straight); ring: a closed, naturally round rod")
    d.add_argument("--control", default=None,
                   help="Bezier control points 'x,y,z; ...' [m] for --shape bezier (scaled to --length)")
    d.add_argument("--n-edges", type=_positive_int, default=40, help="edges per rod (default 40)")
    d.add_argument("--length", type=float, default=0.8, help="rod length [m] (default 0.8)")
    d.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    d.add_argument("--dt", type=float, default=2e-3, help="time step [s] (default 2e-3)")
    d.add_argument("--fps", type=float, default=30.0, help="video frames per second (default 30)")
    d.add_argument("--width", type=int, default=960, help="video width [pixels] (default 960)")
    d.add_argument("--height", type=int, default=540, help="video height [pixels] (default 540)")
    d.add_argument("--camera", default=None, help="camera name (default: the scene's 'main')")
    d.add_argument("--out", default="drop.mp4", help="output MP4 path (default drop.mp4)")
    d.add_argument("--young", type=float, default=2e6, help="Young's modulus E [Pa] (default 2e6)")
    d.add_argument("--radius", type=float, default=0.008, help="rod radius [m] (default 0.008)")
    d.add_argument("--density", type=float, default=1100.0, help="density [kg/m^3] (default 1100)")
    d.add_argument("--seed", type=int, default=0, help="seed of the rods' placement (default 0)")
    d.add_argument("--mode", choices=MODES, default="auto",
                   help="time stepping: implicit (backward Euler, damps swinging), alpha (generalized-alpha: "
                        "keeps it), explicit, projection, auto (default: implicit unless dt is tiny)")
    d.add_argument("--overlay", choices=["none", "frames", "bend", "twist"], default="none",
                   help="draw material frames, or colour rods by bending or twisting strain (default none)")
    d.add_argument("--still", default=None, help="also write the last frame to this PNG")
    d.add_argument("--quality", choices=["auto", "fast", "full"], default="auto",
                   help="rendering: fast (shadow map 1024, no MSAA or reflections: ~5x cheaper on software GL), "
                        "full (the scene's own settings), auto (fast on software GL; default)")
    d.add_argument("--quiet", action="store_true", help="no progress bar")
    d.set_defaults(func=drop)

    hp = sub.add_parser("hair", help="curled strands on a moving head, filmed to an MP4 (headless)")
    hp.add_argument("--strands", type=int, default=1000, help="number of strands (default 1000)")
    hp.add_argument("--vertices", type=_positive_int, default=32, help="vertices per strand (default 32)")
    hp.add_argument("--motion", choices=["shake", "nod", "turn", "still"], default="shake",
                    help="head motion (default shake)")
    hp.add_argument("--seconds", type=float, default=3.0, help="simulated time [s] (default 3)")
    hp.add_argument("--dt", type=float, default=1e-2, help="time step [s] (default 1e-2)")
    hp.add_argument("--fps", type=float, default=25.0, help="video frames per second (default 25)")
    hp.add_argument("--width", type=int, default=960, help="video width [pixels] (default 960)")
    hp.add_argument("--height", type=int, default=540, help="video height [pixels] (default 540)")
    hp.add_argument("--out", default="hair.mp4", help="output MP4 path (default hair.mp4)")
    hp.add_argument("--still", default=None, help="also write the last frame to this PNG")
    hp.add_argument("--strand-contact", action="store_true", help="strands touch one another (default: off)")
    hp.add_argument("--seed", type=int, default=0, help="seed of the roots' jitter and the curls (default 0)")
    hp.add_argument("--quality", choices=["auto", "fast", "full"], default="auto",
                    help="rendering quality, as for drop (default auto)")
    hp.add_argument("--quiet", action="store_true", help="no progress bar")
    hp.set_defaults(func=hair)

    f = sub.add_parser("frames", help="draw a Bezier rod with its Bishop frames to a PNG")
    f.add_argument("--control", default=None,
                   help="control points 'x,y,z; x,y,z; ...' [m], 3k+1 of them (default: a two-segment demo)")
    f.add_argument("--continuity", choices=["C0", "C1"], default="C1", help="join continuity (default C1)")
    f.add_argument("--n-edges", type=_positive_int, default=40, help="edges (default 40)")
    _picture_args(f, 960, 640, "frames.png")
    f.set_defaults(func=frames_cmd)

    c = sub.add_parser("compare", help="sweep cases x backends x n x dt; append records; write a report")
    c.add_argument("--cases", default="cantilever,frequency,circle,drop", help="comma-separated cases")
    c.add_argument("--backends", default="der,flex",
                   help="comma-separated backends (der, flex, cable in .venv317, elastica in .venv-elastica)")
    c.add_argument("--n-edges", default="10,20,50,100", help="comma-separated edge counts")
    c.add_argument("--dt", default="1e-2", help="comma-separated time steps [s]")
    c.add_argument("--modes", default="implicit", help="comma-separated derods modes (implicit, alpha, explicit, "
                                                       "projection)")
    c.add_argument("--young", type=float, default=1e8, help="Young's modulus E [Pa] (default 1e8)")
    c.add_argument("--results", default="results.jsonl", help="JSON-lines results file (appended, resumable)")
    c.add_argument("--report-dir", default="report", help="folder for report.md and its plots")
    c.add_argument("--workers", type=int, default=1, help="parallel processes (default 1)")
    c.add_argument("--report-only", action="store_true", help="only write the report from the results file")
    c.add_argument("--full", action="store_true",
                   help="the sample report's sweep: accuracy, stability map, extreme cases")
    c.set_defaults(func=compare_cmd)

    e = sub.add_parser("edit", help="shape a rod on Bezier curves and simulate it, in a browser (local web app)")
    e.add_argument("--scene", default="floor", help="scene name or MJCF path the rod falls into (default floor)")
    e.add_argument("--host", default="127.0.0.1",
                   help="interface to listen on (default 127.0.0.1: this machine only; 0.0.0.0 exposes it)")
    e.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free one)")
    e.set_defaults(func=edit)

    v = sub.add_parser("view", help="open a scene with rods in MuJoCo's interactive viewer")
    v.add_argument("--scene", default="box", help="scene name or MJCF path (default box)")
    v.add_argument("--rods", type=int, default=3, help="number of rods (default 3)")
    v.add_argument("--shape", choices=["straight", "helix", "bezier"], default="straight")
    v.add_argument("--n-edges", type=_positive_int, default=40, help="edges per rod (default 40)")
    v.set_defaults(func=view)
    from derods.apps import mjcf_run

    mjcf_run.register(sub, v)  # `derods run MODEL.xml`, and `derods view MODEL.xml`

    mi = sub.add_parser("michell", help="twisted rings below and above the critical twist, as a PNG")
    mi.add_argument("--n-edges", type=_positive_int, default=50, help="edges per ring (default 50)")
    mi.add_argument("--below", type=float, default=0.9, help="left ring's twist / Theta_c (default 0.9)")
    mi.add_argument("--above", type=float, default=1.2, help="right ring's twist / Theta_c (default 1.2)")
    mi.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    _picture_args(mi, 960, 480, "michell.png")
    mi.set_defaults(func=michell_cmd)

    p = sub.add_parser("demo", help="build rods from the paper's test cases and print frames and energies")
    p.add_argument("--n-edges", type=_positive_int, default=40, help="edges per rod (default 40)")
    p.add_argument("--young", type=float, default=1e7, help="Young's modulus E [Pa] (default 1e7)")
    p.add_argument("--radius", type=float, default=0.01, help="rod radius [m] (default 0.01)")
    p.add_argument("--density", type=float, default=1000.0, help="density [kg/m^3] (default 1000)")
    p.set_defaults(func=demo)

    b = sub.add_parser("bench", help="run a benchmark case and print one record per run")
    b.add_argument("case", choices=["cantilever", "frequency", "drop", "michell", "circle", "twist", "stability",
                                     "extreme", "oscillation", "coupling", "hair"])
    b.add_argument("--backend", default="der", choices=["der", "flex", "cable", "elastica"],
                   help="der (default), flex (MuJoCo's 1D flexcomp), cable (MuJoCo 3.x: .venv317), "
                        "elastica (PyElastica: .venv-elastica)")
    b.add_argument("--n-edges", type=_positive_int, default=None, help="edges per rod (default 20)")
    b.add_argument("--dt", type=float, default=None,
                   help="time step [s] (default 1e-2; elastica: its largest stable dt, found by search)")
    b.add_argument("--young", type=float, default=None, help="Young's modulus E [Pa] (default 1e8)")
    g = b.add_mutually_exclusive_group()
    g.add_argument("--shear", type=float, default=None, help="shear modulus G [Pa]")
    g.add_argument("--poisson", type=float, default=None, help="Poisson's ratio (default 0.5)")
    b.add_argument("--length", type=float, default=None, help="rod length [m] (default 1)")
    b.add_argument("--radius", type=float, default=None, help="rod radius [m] (default 0.01)")
    b.add_argument("--density", type=float, default=None, help="density [kg/m^3] (default 1000)")
    b.add_argument("--mode", choices=[m for m in MODES if m != "auto"], default=None,
                   help="derods' time stepping (default implicit)")
    b.add_argument("--strands", type=int, default=None, help="hair: number of strands (default 1000)")
    b.add_argument("--vertices", type=_positive_int, default=None, help="hair: vertices per strand (default 32)")
    b.add_argument("--motion", choices=["shake", "nod", "turn", "still"], default=None,
                   help="hair: head motion (default shake)")
    b.add_argument("--seconds", type=float, default=None, help="hair: simulated time [s] (default 1.5)")
    b.add_argument("--strand-contact", action="store_true", help="hair: strands touch one another (default off)")
    b.add_argument("--json", action="store_true", help="print one JSON object per line")
    b.set_defaults(func=bench)
    args = parser.parse_args(argv)
    from derods.sim.divergence import DivergenceError

    previous = signal.signal(signal.SIGTERM, _terminate) if _main_thread() else None
    try:
        return args.func(args)
    except (ValueError, DivergenceError) as err:
        print(f"derods {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"derods {args.command}: interrupted; no partial output was left", file=sys.stderr)
        return 130
    except Terminated:
        print(f"derods {args.command}: terminated; no partial output was left", file=sys.stderr)
        return 143
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every ``finally`` runs (temporary files
    are removed) before the command exits with 143."""


def _terminate(signum, frame):
    raise Terminated


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


if __name__ == "__main__":
    sys.exit(main())
