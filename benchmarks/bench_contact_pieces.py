"""Where a contact step's time goes: the contact stage of a one-rod world taken apart, each
piece timed in a compiled loop (no Python between calls), beside the stage as a step calls it.

Worlds (bench_world's cases, one rod each, so that the contact stage is one block holding
every dof in order, and its pieces can be called on the world's own arrays): ``box`` (drop
n = 50 on the box edge, lying across it), ``floor`` (drop n = 50 on the floor) and ``lying``
(a 32-vertex rod lying on the floor). After ``--settle`` steps the stage's inputs are held
and each piece runs ``--loops`` times in one compiled loop:

* split: MuJoCo's rows sorted into derods' banded and far rows (``split_rows``);
* weights: the rows' weights in the implicit metric (``row_weights``), of which the band of
  A^-1 (``inverse_band``, Takahashi) and diag(J A^-1 J^T) from it (``rows_diag``);
* newton: the Newton solve from a0 (``newton``; its iterations printed), of which one
  factorization of A + J^T W J (``rows_band`` and ``cholesky_into``) and one band solve;
* stage: the whole compiled stage (``contact_step``), and the stage as the step calls it
  (Python, MuJoCo's rows read, the call; median of single calls).

Run: .venv/bin/python benchmarks/bench_contact_pieces.py [--worlds box,floor,lying]
     [--settle 250] [--loops 2000]
"""

from __future__ import annotations

import argparse
import time

import numba as nb
import numpy as np

import derods._numba.contact as _k
from bench_world import drop, strands
from derods._numba.banded import cholesky_into, inverse_band, solve_into
from derods._numba.contact_newton import newton, no_border
from derods._numba.contact_rows import Rows, rows_band, rows_diag
from derods._numba.row_split import split_rows
from derods.sim import contact as stage

WORLDS = {"box": lambda: drop("box")[0](), "floor": lambda: drop("floor")[0](),
          "lying": lambda: strands(1, lying=True)[0]()}


@nb.njit
def _loop(piece, n_loops, efc, system, a0, a_out, force_out, local_of_dof, dof_off, rows, ratio, aref, d, supported,
          width, max_iter, tol):
    """piece n_loops times (0 the stage, 1 split, 2 weights, 3 inverse band, 4 rows' diagonal,
    5 Newton, 6 rows' band, 7 Cholesky, 8 band solve); returns a number read from each
    result, so that none is optimized away."""
    n = len(a0)
    no_cones = _k.cone_groups(np.zeros(0, dtype=np.int64), efc.type, None)
    cones = _k.block_cones(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), efc.type, no_cones, None)
    row, col, val = _k.efc_triplets(efc.is_sparse, efc.nefc, efc.nv, efc.j, efc.rownnz, efc.rowadr, efc.colind)
    lt = np.empty((n, system.a_band.shape[0]))
    x = np.ones(n)
    zb = inverse_band(system.lt, width)
    s = 0.0
    for _ in range(n_loops):
        if piece == 0:
            s += _k.contact_step(efc, None, supported, local_of_dof, dof_off, width, system, a0, a_out, force_out,
                                 max_iter, tol)
        elif piece == 1:
            s += split_rows(row, col, val, local_of_dof, no_cones, np.ones(efc.nefc, dtype=np.bool_), efc.force, n,
                            width)[1]
        elif piece == 2:
            s += _k.row_weights(system, rows, np.zeros((n, 0)), np.zeros((len(d), 0)), np.zeros((0, 0)),
                                np.zeros(0, dtype=np.int64), ratio, np.zeros(n, dtype=np.int64), cones)[0]
        elif piece == 3:
            s += inverse_band(system.lt, width)[0, 0]
        elif piece == 4:
            s += rows_diag(rows.col0, rows.jw, zb)[0]
        elif piece == 5:
            s += newton(system, a0, rows, aref, d, no_border(n, len(d)), None, max_iter, tol)[0][0]
        elif piece == 6:
            s += rows_band(rows.col0, rows.jw, d, n)[0, 0]
        elif piece == 7:
            cholesky_into(system.a_band, lt)
            s += lt[0, 0]
        elif piece == 8:
            solve_into(system.lt, x, 0, n)
            s += x[0]
    return s


def median_call_us(fn, calls: int) -> float:
    """Median time [us] of ``calls`` single calls of fn()."""
    t = np.empty(calls)
    for k in range(calls):
        t0 = time.perf_counter()
        fn()
        t[k] = time.perf_counter() - t0
    return float(np.median(t)) * 1e6


def run(name: str, settle: int, loops: int) -> dict:
    world = WORLDS[name]()
    world.step(settle)
    step, data = world._step, world.data
    contact = step.contact
    efc = contact.rows(data)
    system = step.system.arrays
    n = len(step.a0)
    # The rows as the stage splits them (one block holding every dof: MuJoCo's numbering).
    row, col, val = _k.efc_triplets(efc.is_sparse, efc.nefc, efc.nv, efc.j, efc.rownnz, efc.rowadr, efc.colind)
    no_group = np.zeros(0, dtype=np.int64)
    mine, kb, col0, jw, far, _ = split_rows(row, col, val, contact.local_of_dof, no_group,
                                            np.ones(efc.nefc, dtype=np.bool_), efc.force, n, stage.WINDOW)
    rows = Rows(col0, jw, *far)
    ratio = efc.r[mine] / efc.diag_a[mine]
    aref = efc.aref[mine].copy()
    cones = _k.block_cones(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), efc.type, no_group, None)
    d = _k.row_weights(system, rows, np.zeros((n, 0)), np.zeros((len(mine), 0)), np.zeros((0, 0)),
                       np.zeros(0, dtype=np.int64), ratio, np.zeros(n, dtype=np.int64), cones)
    iterations = newton(system, step.a0, rows, aref, d, no_border(n, len(mine)), None, stage.MAX_ITER, stage.TOL)[3]
    args = (efc, system, step.a0, contact.a.copy(), contact.force.copy(), contact.local_of_dof, contact.dof_off, rows,
            ratio, aref, d, stage.SUPPORTED, stage.WINDOW, stage.MAX_ITER, stage.TOL)
    out = {"world": name, "dofs": n, "rows": int(data.nefc), "banded": int(kb), "far": len(far[0]) - 1,
           "newton_iterations": int(iterations)}
    labels = ["stage", "split", "weights", "inverse band", "rows' diagonal", "newton", "rows' band", "cholesky",
              "band solve"]
    for piece, label in enumerate(labels):
        _loop(piece, 1, *args)
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            _loop(piece, loops, *args)
            best = min(best, (time.perf_counter() - t0) / loops * 1e6)
        out[label] = best
    out["stage as stepped"] = median_call_us(lambda: contact(data, step.system, step.a0), loops)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worlds", default="box,floor,lying")
    ap.add_argument("--settle", type=int, default=250)
    ap.add_argument("--loops", type=int, default=2000)
    args = ap.parse_args()
    print("the contact stage of one rod, us per call (compiled loops: best of 3; as stepped: median)")
    for name in args.worlds.split(","):
        r = run(name, args.settle, args.loops)
        print(f"{name}: {r['dofs']} dofs, {r['rows']} rows ({r['banded']} banded, {r['far']} far), "
              f"Newton {r['newton_iterations']} iterations")
        for key in ("stage as stepped", "stage", "split", "weights", "inverse band", "rows' diagonal", "newton",
                    "rows' band", "cholesky", "band solve"):
            print(f"  {key:18s} {r[key]:7.1f}")


if __name__ == "__main__":
    main()
