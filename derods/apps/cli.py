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

This module reads the options (the picture commands' shared ones come from one function,
:func:`_picture_options`) and turns errors and signals into exit codes; what each command
then does is in :mod:`derods.apps.commands`.
"""

from __future__ import annotations

import argparse
import signal
import sys

from . import commands


def _positive_int(text: str) -> int:
    v = int(text)
    if v < 2:
        raise argparse.ArgumentTypeError(f"must be an integer >= 2, got {text}")
    return v


def _count(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return v


def _picture_options(parser: argparse.ArgumentParser, width: int, height: int, out: str, *, fps: float | None = None,
                     camera: str | None = None) -> None:
    """Add the options the picture commands share, worded the same for each, as one group of
    ``parser``: --width and --height [pixels] and --out (a PNG); for a video (``fps``: its
    default frame rate) --out is an MP4 and --fps, --still (the last frame as a PNG),
    --quality and --quiet come too; --camera when ``camera`` (the default camera, in words)
    is given."""
    from derods.viz.render import QUALITIES

    kind = "image" if fps is None else "video"
    group = parser.add_argument_group(f"{kind} options")
    if fps is not None:
        group.add_argument("--fps", type=float, default=fps, help=f"video frames per second (default {fps:g})")
    group.add_argument("--width", type=int, default=width, help=f"{kind} width [pixels] (default {width})")
    group.add_argument("--height", type=int, default=height, help=f"{kind} height [pixels] (default {height})")
    if camera is not None:
        group.add_argument("--camera", default=None, help=f"camera name (default: {camera})")
    group.add_argument("--out", default=out, help=f"output {'PNG' if fps is None else 'MP4 path'} (default {out})")
    if fps is not None:
        group.add_argument("--still", default=None, help="also write the last frame to this PNG")
        group.add_argument("--quality", choices=("auto",) + tuple(QUALITIES), default="auto",
                           help="rendering: fast (shadow map 1024, no MSAA or reflections: ~5x cheaper on software "
                                "GL), full (the scene's own settings), auto (fast on software GL; default)")
        group.add_argument("--quiet", action="store_true", help="no progress bar")


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
    d.add_argument("--young", type=float, default=2e6, help="Young's modulus E [Pa] (default 2e6)")
    d.add_argument("--radius", type=float, default=0.008, help="rod radius [m] (default 0.008)")
    d.add_argument("--density", type=float, default=1100.0, help="density [kg/m^3] (default 1100)")
    d.add_argument("--seed", type=int, default=0, help="seed of the rods' placement (default 0)")
    d.add_argument("--mode", choices=MODES, default="auto",
                   help="time stepping: implicit (backward Euler, damps swinging), alpha (generalized-alpha: "
                        "keeps it), explicit, projection, auto (default: implicit unless dt is tiny)")
    d.add_argument("--overlay", choices=["none", "frames", "bend", "twist"], default="none",
                   help="draw material frames, or colour rods by bending or twisting strain (default none)")
    _picture_options(d, 960, 540, "drop.mp4", fps=30.0, camera="the scene's 'main'")
    d.set_defaults(func=commands.drop)

    hp = sub.add_parser("hair", help="curled strands on a moving head, filmed to an MP4 (headless)")
    hp.add_argument("--strands", type=int, default=1000, help="number of strands (default 1000)")
    hp.add_argument("--vertices", type=_positive_int, default=32, help="vertices per strand (default 32)")
    hp.add_argument("--motion", choices=["shake", "nod", "turn", "still"], default="shake",
                    help="head motion (default shake)")
    hp.add_argument("--seconds", type=float, default=3.0, help="simulated time [s] (default 3)")
    hp.add_argument("--dt", type=float, default=1e-2, help="time step [s] (default 1e-2)")
    hp.add_argument("--strand-contact", action="store_true", help="strands touch one another (default: off)")
    hp.add_argument("--seed", type=int, default=0, help="seed of the roots' jitter and the curls (default 0)")
    _picture_options(hp, 960, 540, "hair.mp4", fps=25.0)
    hp.set_defaults(func=commands.hair)

    f = sub.add_parser("frames", help="draw a Bezier rod with its Bishop frames to a PNG")
    f.add_argument("--control", default=None,
                   help="control points 'x,y,z; x,y,z; ...' [m], 3k+1 of them (default: a two-segment demo)")
    f.add_argument("--continuity", choices=["C0", "C1"], default="C1", help="join continuity (default C1)")
    f.add_argument("--n-edges", type=_positive_int, default=40, help="edges (default 40)")
    _picture_options(f, 960, 640, "frames.png")
    f.set_defaults(func=commands.frames_cmd)

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
    c.add_argument("--dask", metavar="ADDRESS", default=None,
                   help="run the jobs on the dask.distributed cluster whose scheduler is at ADDRESS "
                        "(tcp://host:8786; needs derods[dask]); this process alone writes the results")
    c.add_argument("--report-only", action="store_true", help="only write the report from the results file")
    c.add_argument("--full", action="store_true",
                   help="the sample report's sweep: accuracy, stability map, extreme cases")
    c.set_defaults(func=commands.compare_cmd)

    e = sub.add_parser("edit", help="shape a rod on Bezier curves and simulate it, in a browser (local web app)")
    e.add_argument("--scene", default="floor", help="scene name or MJCF path the rod falls into (default floor)")
    e.add_argument("--host", default="127.0.0.1",
                   help="interface to listen on (default 127.0.0.1: this machine only; 0.0.0.0 exposes it)")
    e.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free one)")
    e.set_defaults(func=commands.edit)

    v = sub.add_parser("view", help="open a scene with rods in MuJoCo's interactive viewer")
    v.add_argument("--scene", default="box", help="scene name or MJCF path (default box)")
    v.add_argument("--rods", type=int, default=3, help="number of rods (default 3)")
    v.add_argument("--shape", choices=["straight", "helix", "bezier"], default="straight")
    v.add_argument("--n-edges", type=_positive_int, default=40, help="edges per rod (default 40)")
    v.set_defaults(func=commands.view)
    from derods.apps import mjcf_run

    mjcf_run.register(sub, v)  # `derods run MODEL.xml`, and `derods view MODEL.xml`

    mi = sub.add_parser("michell", help="twisted rings below and above the critical twist, as a PNG")
    mi.add_argument("--n-edges", type=_positive_int, default=50, help="edges per ring (default 50)")
    mi.add_argument("--below", type=float, default=0.9, help="left ring's twist / Theta_c (default 0.9)")
    mi.add_argument("--above", type=float, default=1.2, help="right ring's twist / Theta_c (default 1.2)")
    mi.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    _picture_options(mi, 960, 480, "michell.png")
    mi.set_defaults(func=commands.michell_cmd)

    p = sub.add_parser("demo", help="build rods from the paper's test cases and print frames and energies")
    p.add_argument("--n-edges", type=_positive_int, default=40, help="edges per rod (default 40)")
    p.add_argument("--young", type=float, default=1e7, help="Young's modulus E [Pa] (default 1e7)")
    p.add_argument("--radius", type=float, default=0.01, help="rod radius [m] (default 0.01)")
    p.add_argument("--density", type=float, default=1000.0, help="density [kg/m^3] (default 1000)")
    p.set_defaults(func=commands.demo)

    b = sub.add_parser("bench", help="run a benchmark case and print one record per run")
    b.add_argument("case", choices=["cantilever", "frequency", "drop", "michell", "circle", "twist", "stability",
                                     "extreme", "oscillation", "coupling", "hair", "pile"])
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
    b.add_argument("--vertices", type=_positive_int, default=None,
                   help="hair: vertices per strand (default 32); pile: per cable (default 41)")
    b.add_argument("--cables", type=_count, default=None, help="pile: number of cables (default 100)")
    b.add_argument("--margin", type=float, default=None,
                   help="pile: the cables' contact margin [m] (speculative contacts; default 0)")
    b.add_argument("--speculative", action="store_true",
                   help="pile: contact margins sized by each cable's speed (default off)")
    b.add_argument("--motion", choices=["shake", "nod", "turn", "still"], default=None,
                   help="hair: head motion (default shake)")
    b.add_argument("--seconds", type=float, default=None, help="hair, pile: simulated time [s] (default 1.5, 2)")
    b.add_argument("--strand-contact", action="store_true", help="hair: strands touch one another (default off)")
    b.add_argument("--repeats", type=_count, default=None,
                   help="timed runs after an untimed first one; us/step is the median over steps and runs "
                        "(default 3; not hair or pile: their median over steps is taken in one run)")
    b.add_argument("--json", action="store_true", help="print one JSON object per line")
    b.set_defaults(func=commands.bench)
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
