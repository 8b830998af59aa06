"""Sweeps of the benchmark cases over backends and resolutions.

:func:`sweep` runs every combination of cases x backends x n_edges x dt (x
modes for derods) through :func:`derods.bench.run` and appends one JSON
record per run to a results file as soon as it finishes: a crash or Ctrl-C
loses nothing, and a re-run skips what the file already holds. Runs go through
any ``concurrent.futures.Executor`` (``--workers N`` uses a process pool; ``--dask
ADDRESS`` a running dask.distributed cluster, :func:`dask_executor`). Whatever runs the jobs,
only this process writes the results file, a job's records in one append. Records from other
environments (say, MuJoCo 3.17 for the cable) appended to the same file are
merged into the same report (:mod:`derods.bench.report`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import json
import os
import pathlib
import sys

from . import elastica
from .command import run
from .params import BACKEND_CASES, BACKENDS, CASES, CaseParams

#: The fields that identify a run (a re-run with the same ones is skipped).
KEY_FIELDS = ("case", "backend", "n_edges", "dt", "mode", "young", "length", "radius", "density")
ACCURACY_CASES = ("cantilever", "frequency", "circle", "michell", "twist")
#: The fields of a record that say what a run cost on the machine that ran it: the only
#: ones in which two runs of the same job may differ (:func:`without_timing`).
TIMING_FIELDS = ("wall_s", "us_per_step", "us_per_step_repeats")


def without_timing(rec: dict) -> dict:
    """A record without its :data:`TIMING_FIELDS`: what any run of the same job, in any
    process or on any machine of the same environment, gives alike."""
    return {k: v for k, v in rec.items() if k not in TIMING_FIELDS}


@dataclasses.dataclass(frozen=True)
class Job:
    case: str
    params: CaseParams

    def key(self) -> tuple:
        p = self.params
        mode = p.build.mode(p)
        return (self.case, p.backend, p.n_edges, float(p.dt), mode, float(p.young), float(p.length),
                float(p.radius), float(p.density))


def record_key(rec: dict) -> tuple:
    return tuple(float(rec[k]) if isinstance(rec[k], (int, float)) and k not in ("n_edges",) else rec[k]
                 for k in KEY_FIELDS)


def load(path) -> list[dict]:
    """Records of a results file (JSON lines); a torn last line from a crash is ignored."""
    path = pathlib.Path(path)
    if not path.exists():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return out


def available(backend: str) -> str | None:
    """None if this MuJoCo can run ``backend``, else the message saying how to get it."""
    try:
        CaseParams(backend=backend)
    except ValueError as err:
        return str(err)
    return None


def plan(cases, backends, n_edges, dts, modes=("implicit",), young=1e8, **params) -> list[Job]:
    """Every supported combination as a list of jobs; a backend this MuJoCo lacks is
    skipped with a message on stderr saying how to get it. Unknown case or backend names
    raise ValueError with the choices."""
    for name, given, known in (("case", cases, CASES), ("backend", backends, BACKENDS)):
        unknown = [c for c in given if c not in known]
        if unknown:
            raise ValueError(f"unknown {name} {', '.join(map(repr, unknown))}; choose from {', '.join(known)}")
    usable = []
    for backend in backends:
        why = available(backend)
        if why is None:
            usable.append(backend)
        else:
            print(f"skipping backend {backend!r}: {why}", file=sys.stderr)
    jobs = []
    for case in cases:
        for backend in usable:
            if case not in BACKEND_CASES.get(backend, ()):
                continue
            for n in n_edges:
                # PyElastica is explicit: it runs at its own largest stable dt, whatever the plan's.
                for dt in (dts if backend != "elastica" else [None]):
                    for mode in (modes if backend == "der" else ("implicit",)):
                        p = CaseParams(n_edges=n, dt=dt or 1.0, young=young, mode=mode, backend=backend,
                                             **params)
                        if dt is None:
                            p = dataclasses.replace(p, dt=elastica.search_dt(p))
                        jobs.append(Job(case, p))
    return jobs


#: The sample report's sweep: (cases, backends, n_edges, dts, extra parameters).
ALL = ["der", "flex", "cable", "elastica"]
_RING = {"young": 1e7, "radius": 0.005, "shear": 5e6}
#: derods' modes in the accuracy and oscillation rows: backward Euler and generalized-alpha.
MODES = {"modes": ("implicit", "alpha")}
FULL_PLAN = [
    (["cantilever"], ALL, [10, 20, 50, 100, 200], [1e-2], MODES),
    (["circle"], ALL, [10, 20, 50, 100, 200], [1e-2], {}),
    (["frequency"], ALL, [10, 20, 50, 100], [1e-3], MODES),
    (["drop"], ALL, [20, 50], [2e-3, 1e-2], {"young": 1e7} | MODES),
    (["michell"], ALL, [20, 50], [1e-3, 1e-2], _RING),
    # The cable's O(n^3) step makes a 100-segment ring bisection take minutes at dt = 1e-3.
    (["michell"], ["der", "flex"], [100], [1e-3, 1e-2], _RING),
    (["extreme"], ALL, [50], [2e-3], {}),
    (["oscillation"], ALL, [20, 50], [1e-3, 3e-3, 1e-2], {"young": 1e9} | MODES),
]
STABILITY_E = [1e5, 1e7, 1e9, 1e11]
STABILITY_DT = [1e-4, 1e-3, 1e-2, 2e-2]
STABILITY_N = [10, 50, 200, 400]


def full_plan(backends=("der", "flex")) -> list[Job]:
    """Every run of the sample report for these backends: accuracy sweeps, the stability
    map, extreme cases. (The cable runs in MuJoCo 3.17: ``backends=("cable",)`` there; PyElastica
    in its own environment: ``backends=("elastica",)``.)"""
    jobs = []
    for cases, plan_backends, ns, dts, extra in FULL_PLAN:
        chosen = [b for b in plan_backends if b in backends]
        jobs += plan(cases, chosen, ns, dts, **({"young": 1e8} | extra))
    for young in STABILITY_E:
        for backend in backends:
            # The cable's dense joint chain costs O(n^3) per step: 12 ms at n = 200.
            ns = [n for n in STABILITY_N if n <= 200] if backend == "cable" else STABILITY_N
            jobs += plan(["stability"], [backend], ns, STABILITY_DT, young=young, **MODES)
    return jobs


def _run(job: Job) -> list[dict]:
    try:
        return run(job.case, job.params)
    except Exception as err:  # a record of the failure is itself a result
        p = job.params
        return [{"case": job.case, "backend": p.backend, "n_edges": p.n_edges, "dt": p.dt,
                 "mode": p.build.mode(p),
                 "young": p.young, "length": p.length,
                 "radius": p.radius, "density": p.density, "stable": False, "measured": None,
                 "rel_error": None, "wall_s": 0.0, "note": f"{type(err).__name__}: {err}"}]


def sweep(jobs: list[Job], results, executor: concurrent.futures.Executor | None = None,
          progress: bool = True) -> int:
    """Run the jobs not yet in ``results`` (a JSON-lines file), appending records as they finish.

    executor: where to run them (default: in this process). Returns the number of runs made.
    """
    results = pathlib.Path(results)
    if not results.parent.is_dir():
        raise ValueError(f"results folder {str(results.parent)!r} does not exist; create it first")
    done = {record_key(r) for r in load(results)}
    todo = [j for j in jobs if j.key() not in done]
    if progress:
        print(f"{len(jobs) - len(todo)} of {len(jobs)} runs already in {results}; {len(todo)} to go",
              file=sys.stderr)

    def write(records):
        # A crash may have left a torn last line: start on a fresh one.
        if results.exists() and results.stat().st_size:
            with open(results, "rb") as f:
                f.seek(-1, os.SEEK_END)
                torn = f.read(1) != b"\n"
            if torn:
                with open(results, "a") as f:
                    f.write("\n")
        # One write of whole lines: a job's records land together or (torn) not at all.
        with open(results, "a") as f:
            f.write("".join(json.dumps(rec) + "\n" for rec in records))
            f.flush()
            os.fsync(f.fileno())

    if executor is None:
        for i, job in enumerate(todo):
            write(_run(job))
            if progress:
                print(f"[{i + 1}/{len(todo)}] {job.case} {job.params.backend} n={job.params.n_edges} "
                      f"dt={job.params.dt:g}", file=sys.stderr)
    else:
        futures = {executor.submit(_run, job): job for job in todo}
        for i, fut in enumerate(concurrent.futures.as_completed(futures)):
            write(fut.result())
            if progress:
                job = futures[fut]
                print(f"[{i + 1}/{len(todo)}] {job.case} {job.params.backend} n={job.params.n_edges} "
                      f"dt={job.params.dt:g}", file=sys.stderr)
    return len(todo)


def _worker_environment() -> dict:
    """What a worker runs with (called on each worker by :func:`dask_executor`)."""
    import mujoco
    import numpy as np

    import derods

    return {"derods": derods.__version__, "mujoco": mujoco.__version__, "numpy": np.__version__,
            "python": sys.version.split()[0]}


@contextlib.contextmanager
def dask_executor(address: str, wait_s: float = 60.0):
    """An executor running jobs on the dask.distributed cluster whose scheduler is at
    ``address`` (``tcp://host:8786``), for :func:`sweep`.

    Before any job it waits up to ``wait_s`` [s] for a worker, checks that every worker
    imports derods (a ValueError says which cannot), and warns on stderr where a worker's
    derods, MuJoCo, NumPy or Python differ from this process's (its records say which MuJoCo
    ran them). Each job is submitted as its own task (never merged with an equal one); the
    workers return records and only the caller writes them. Needs ``pip install
    'derods[dask]'``."""
    try:
        from dask.distributed import Client
    except ImportError as err:
        raise ValueError("--dask needs dask.distributed: pip install 'derods[dask]' "
                         "(or pip install 'dask[distributed]')") from err
    try:
        client = Client(address, timeout=wait_s)
    except OSError as err:
        raise ValueError(f"no dask scheduler reached at {address!r}: {err}") from err
    with client:
        try:
            client.wait_for_workers(1, timeout=wait_s)
        except TimeoutError as err:
            raise ValueError(f"the dask scheduler at {address!r} has no worker after {wait_s:g} s") from err
        try:
            envs = client.run(_worker_environment)
        except ImportError as err:
            raise ValueError(f"a dask worker cannot import derods ({err}): install derods in the workers' "
                             "environment (pip install -e . or the same wheel), or start them with "
                             "PYTHONPATH naming the repository") from err
        here = _worker_environment()
        for worker, env in sorted(envs.items()):
            if env != here:
                print(f"warning: dask worker {worker} runs {env}, this process {here}", file=sys.stderr)
        yield client.get_executor(pure=False)
