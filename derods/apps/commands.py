"""What each ``derods`` subcommand does once its options are read: the functions
:mod:`derods.apps.cli` calls with the parsed arguments. Each returns the exit code;
errors are raised (``ValueError``, :class:`derods.DivergenceError`) for the command line
to report.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

#: Control points [m] of the demo's two-segment cubic Bezier curve.
DEMO_CONTROL_POINTS = np.array([
    [0.0, 0.0, 0.0], [0.3, 0.4, 0.0], [0.6, 0.5, 0.2], [1.0, 0.3, 0.2],
    [1.2, -0.3, 0.5], [1.5, 0.0, 0.0], [1.8, 0.4, 0.1],
])


def demo(args: argparse.Namespace) -> int:
    """Bezier rods with C0 and C1 joins, a clamped twisted rod and a twisted ring."""
    import derods
    from derods import frames, geometry, reference, shapes
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
          f"{reference.twist_energy(mat.beta, 2 * np.pi, l_eff):.6g} J (L' = {l_eff:g} m between the clamped edges)")

    print("\n3. A naturally straight ring twisted by Theta (Michell's test case)")
    theta_c = reference.michell_critical_twist(mat.alpha, mat.beta)
    ring = derods.Rod(shapes.circle(0.25, n), mat, closed=True, natural_curvature=False,
                      boundary=TwistBoundary("ring", total_twist=0.5 * theta_c))
    rs = ring.advance(ring.rest_state(), ring.rest_x)
    bend = ring.derivatives(rs, 0, terms=("bend_isotropic",)).energy
    tw = ring.derivatives(rs, 0, terms=("twist",)).energy
    print(f"   critical twist 2 pi sqrt(3) alpha / beta = {theta_c:.4f} rad; at Theta = Theta_c / 2: "
          f"bending {bend:.6g} J (pi alpha / R = {reference.circle_bending_energy(mat.alpha, 0.25):.6g}), "
          f"twist {tw:.6g} J")
    return 0


def _before_filming(out, still, params) -> None:
    """Refuse what can be refused (the output paths; seconds, fps and dt that do not make
    whole frames) before the compiled kernels are prepared, then prepare them."""
    from derods.sim import warmup
    from derods.viz import filming, output

    output.check_outputs(out, still)
    filming.frame_plan(params.seconds, params.fps, params.dt)
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


def require_display(video_command: str) -> None:
    """Refuse to open MuJoCo's viewer without a display, naming ``video_command`` (the
    headless command that writes a video instead)."""
    import os

    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise ValueError("derods view needs a display and none is set (DISPLAY); run it on a desktop, "
                         f"or write a video with '{video_command}'")


def show(world) -> None:
    """``world`` in MuJoCo's viewer, stepped in real time (60 frames per second) until the
    window closes; drag a rod with the mouse (double-click it, then Ctrl + right-drag) and
    the pull enters the implicit step."""
    import time

    import mujoco.viewer

    h = world.model.opt.timestep
    with mujoco.viewer.launch_passive(world.model, world.data) as viewer:
        while viewer.is_running():
            start = time.perf_counter()
            world.step(max(1, int(round(1 / (60 * h)))))
            viewer.sync()
            time.sleep(max(0.0, 1 / 60 - (time.perf_counter() - start)))


def view(args: argparse.Namespace) -> int:
    """``derods view``: the drop scene in MuJoCo's viewer (:func:`show`)."""
    require_display("derods drop")
    from derods.apps import drop as drop_mod

    params = drop_mod.DropParams(scene=args.scene, rods=args.rods, shape=args.shape, n_edges=args.n_edges)
    show(drop_mod.build_world(params))
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
    if args.dask and args.workers > 1:
        raise ValueError("--dask and --workers choose where the jobs run: give one of them")
    if jobs and args.dask:
        with sweep.dask_executor(args.dask) as ex:
            sweep.sweep(jobs, results, ex)
    elif jobs and args.workers > 1:
        with concurrent.futures.ProcessPoolExecutor(args.workers) as ex:
            sweep.sweep(jobs, results, ex)
    elif jobs:
        sweep.sweep(jobs, results)
    path = report.report(results, args.report_dir, command="python -m derods " + " ".join(sys.argv[1:]))
    print(f"wrote {path}")
    return 0


def bench(args: argparse.Namespace) -> int:
    """``derods bench CASE``: see :mod:`derods.bench.cases` (hair: :mod:`derods.bench.hair`, pile:
    :mod:`derods.bench.pile`)."""
    from derods import bench as bench_mod

    if args.case in ("hair", "pile") and args.repeats is not None:
        raise ValueError(f"--repeats is not an option of the {args.case} case (its median step is taken over one "
                         "run)")
    for name in ("cables", "margin"):
        if args.case != "pile" and getattr(args, name) is not None:
            raise ValueError(f"--{name} is an option of the pile case only")
    if args.case != "pile" and args.speculative:
        raise ValueError("--speculative is an option of the pile case only")
    if args.case == "pile":
        from derods.bench import pile

        for name in ("strands", "motion"):
            if getattr(args, name) is not None:
                raise ValueError(f"--{name} is an option of the hair case only")
        if args.strand_contact:
            raise ValueError("--strand-contact is an option of the hair case only (the pile's cables always touch)")
        given = {k: v for k, v in (("cables", args.cables), ("vertices", args.vertices), ("dt", args.dt),
                                   ("seconds", args.seconds), ("margin", args.margin),
                                   ("backend", args.backend)) if v is not None}
        given["speculative"] = args.speculative
        return pile.main(pile.PileCase(**given), args.json)
    if args.case == "hair":
        from derods.bench import hair as hair_bench

        given = {k: getattr(args, k) for k in ("strands", "vertices", "dt", "motion", "seconds", "backend")
                 if getattr(args, k) is not None}
        given["strand_contact"] = args.strand_contact
        return hair_bench.main(hair_bench.HairCase(**given), args.json)
    for name in ("strands", "motion"):
        if getattr(args, name) is not None:
            raise ValueError(f"--{name} is an option of the hair case only")
    for name in ("vertices", "seconds"):
        if getattr(args, name) is not None:
            raise ValueError(f"--{name} is an option of the hair and pile cases only")
    if args.strand_contact:
        raise ValueError("--strand-contact is an option of the hair case only")
    return bench_mod.main(args.case, bench_mod.params_from_args(args), args.json,
                         repeats=3 if args.repeats is None else args.repeats)
