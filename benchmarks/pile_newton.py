"""Where a heap's contact solve spends its iterations: the pile (derods/bench/pile.py) is
stepped to a heap, and at a few steps the contact problem of its largest block of rods
(one block: every cable touches the heap) is caught as the compiled Newton solve receives
it (:func:`derods._numba.contact_newton.newton`). The same problem is then solved again
in numpy/scipy, Newton's method as the compiled one runs it (exact line search, the same
stopping rule), with Newton's direction from

* ``band-cg``: conjugate gradients preconditioned with the band B and the far rows' own
  blocks, to Eisenstat and Walker's forcing term, as derods does (the check: the same
  Newton iterations as the compiled solve);
* ``exact``: a sparse LU factor of the whole Hessian H = A + J^T W J, every iteration
  (what no preconditioner can beat: Newton's own iteration count);
* ``lagged``: CG preconditioned with the exact factor of the first iteration's H;
* ``coarse``: B plus a coarse correction on each cable's piecewise-linear motions (segments
  of ``--segment`` vertices), balanced (two more products with H an iteration);

and at looser tolerances than the solve's 1e-10. Between consecutive steps it counts the
rows whose state (active or not) at the solution persists, matched by contact (the geom
pair, the contact's rank among the pair's, the row within it), and Newton's iterations
from the last step's active set. It also times a sparse factorization of H (scipy's
SuperLU, COLAMD) against the step.

Run: .venv/bin/python benchmarks/pile_newton.py [--cables 100] [--steps 61,62,119,120]
     [--segment 5]

The catch runs one step in the stage's Python source (numba's ``py_func``, the compiled
kernels below it as they are), which gives the same result to the bit; it takes a few
seconds a step.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla

import derods._numba.contact as stage
from derods._numba.contact_cg import far_blocks_into_band, forcing
from derods._numba.contact_rows import exact_line_search, rows_band_into
from derods._numba.implicit import System
from derods.bench import pile
from derods.sim.contact import MAX_ITER, SUPPORTED, TOL, WINDOW


def catch(world, steps: list[int]) -> dict[int, dict]:
    """Step ``world`` to the last of ``steps``; at each, the largest block's Newton problem."""
    caught, meta = {}, {}
    newton, block_cones = stage.newton, stage.block_cones

    def newton_spy(system, a, rows, aref, d, border, cones, max_iter, tol):
        caught.setdefault("calls", []).append(dict(
            system=System(*(np.array(x) if isinstance(x, np.ndarray) else x for x in system)),
            rows=tuple(np.array(x) for x in rows), a0=a.copy(), aref=aref.copy(), d=d.copy(),
            mj_rows=meta["mj_rows"]))
        return newton(system, a, rows, aref, d, border, cones, max_iter, tol)

    def cones_spy(efc, efc_rows, *rest):
        meta["mj_rows"] = np.asarray(efc_rows)[np.asarray(efc)]
        return block_cones(efc, efc_rows, *rest)

    contact = world._step.contact

    def solve_in_python(data, system, local_of_dof, dof_off, a0, a_out, force_out, efc=None):
        rows = contact.rows(data)
        blocks = stage.contact_blocks(rows, SUPPORTED, local_of_dof, dof_off, system, a0, a_out, force_out)
        stage.solve_blocks.py_func(rows, None, blocks, 0, blocks.n_blocks, local_of_dof, dof_off, WINDOW, system, a0,
                                   a_out, force_out, MAX_ITER, TOL)
        return 1

    out = {}
    saved = (stage.newton, stage.block_cones, stage.solve_block, stage.solve_split)
    try:
        stage.newton, stage.block_cones = newton_spy, cones_spy
        stage.solve_block, stage.solve_split = stage.solve_block.py_func, stage.solve_split.py_func
        for k in range(max(steps) + 1):
            if k not in steps:
                world.step()
                continue
            caught.clear()
            contact._solve = solve_in_python
            world.step()
            del contact._solve
            big = max(caught["calls"], key=lambda c: len(c["a0"]))
            d = world.data
            big.update(efc_id=d.efc_id[:d.nefc].copy(), geom=d.contact.geom[:d.ncon].copy())
            out[k] = big
    finally:
        stage.newton, stage.block_cones, stage.solve_block, stage.solve_split = saved
    return out


class Problem:
    """One caught contact problem as sparse matrices: A (the implicit step's matrix), J
    (every row), the rows' weights d and reference accelerations aref, the start a0."""

    def __init__(self, c: dict):
        self.c = c
        system = c["system"]
        col0, jw, fptr, fcol, fval = c["rows"]
        self.system, self.col0, self.jw, self.far = system, col0, jw, (fptr, fcol, fval)
        n, kb = len(c["a0"]), len(col0)
        r_i, c_i, v_i = [], [], []
        for i in range(kb):
            for q in range(jw.shape[1]):
                if col0[i] + q < n and jw[i, q] != 0.0:
                    r_i.append(i), c_i.append(col0[i] + q), v_i.append(jw[i, q])
        for r in range(len(fptr) - 1):
            for p in range(fptr[r], fptr[r + 1]):
                r_i.append(kb + r), c_i.append(fcol[p]), v_i.append(fval[p])
        self.J = sp.csr_matrix((v_i, (r_i, c_i)), shape=(len(c["aref"]), n))
        ab = system.a_band
        A = sp.diags(ab[0])
        for k in range(1, ab.shape[0]):
            off = sp.diags(ab[k][:n - k], -k, shape=(n, n))
            A = A + off + off.T
        self.A = A.tocsr()
        self.n, self.kb = n, kb
        self.a0, self.aref, self.d = c["a0"], c["aref"], c["d"]

    def hessian(self, w):
        return (self.A + self.J.T @ sp.diags(w) @ self.J).tocsr()

    def band(self, w):
        """B: A's band with the banded rows and the far rows' own blocks (derods' preconditioner)."""
        ab = self.system.a_band.copy()
        extra = np.empty_like(ab)
        rows_band_into(self.col0, self.jw, np.ascontiguousarray(w[:self.kb]), extra)
        ab += extra
        far_blocks_into_band(ab, *self.far, np.ascontiguousarray(w[self.kb:]))
        return ab

    def keys(self) -> list[tuple]:
        """Each row's contact identity: geom pair, the contact's rank among the pair's, row in it."""
        efc_id, geom = self.c["efc_id"], self.c["geom"]
        first, rank, seen = {}, {}, {}
        for r, ci in enumerate(efc_id):
            first.setdefault(ci, r)
        for ci, g in enumerate(geom):
            pair = (int(g[0]), int(g[1]))
            rank[ci] = seen.get(pair, 0)
            seen[pair] = rank[ci] + 1
        return [(int(geom[efc_id[r]][0]), int(geom[efc_id[r]][1]), rank[efc_id[r]], int(r - first[efc_id[r]]))
                for r in self.c["mj_rows"]]


def pcg(H, b, prec, tol, max_iter=2000):
    """Preconditioned CG from zero to |r| <= tol |b|; (x, iterations)."""
    x, r = np.zeros_like(b), b.copy()
    z = prec(r)
    p, rz, bn = z.copy(), r @ z, np.linalg.norm(b)
    for it in range(1, max_iter + 1):
        hp = H @ p
        alpha = rz / (p @ hp)
        x += alpha * p
        r -= alpha * hp
        if np.linalg.norm(r) <= tol * bn:
            return x, it
        z = prec(r)
        rz_new = r @ z
        p = z + rz_new / rz * p
        rz = rz_new
    return x, max_iter


def newton(pb: Problem, direction: str, tol: float = TOL, guess=None, segment: int = 5):
    """Newton's method as the compiled solve runs it; (a, Newton iterations, CG iterations).
    guess: a first active set (bool per row) whose Hessian and gradient make the first step."""
    A, J, d, aref, a0 = pb.A, pb.J, pb.d, pb.aref, pb.a0
    a, am, jar = a0.copy(), np.zeros(pb.n), J @ a0 - aref
    scale = np.abs(pb.system.mass * a0).max() + np.abs(d * aref).max() + 1e-300
    eta, g_prev, cg_total, first = 0.1, 0.0, 0, None
    coarse = _coarse_basis(pb.n, segment) if direction == "coarse" else None
    it = 0
    for it in range(1, MAX_ITER + 1):
        w = np.where(jar < 0, d, 0.0)
        true_grad = grad = J.T @ (w * jar) + am
        gmax = np.abs(grad).max()
        if gmax <= tol * scale:
            break
        eta = forcing(eta, gmax, g_prev)
        g_prev = gmax
        if it == 1 and guess is not None:  # the step's model from the guessed active set
            w = np.where(guess, d, 0.0)
            grad = J.T @ (w * jar) + am
        H = pb.hessian(w)
        if direction == "exact":
            delta, cg = sla.splu(H.tocsc(), permc_spec="COLAMD").solve(-grad), 0
        else:
            if direction == "lagged":
                first = first or sla.splu(H.tocsc(), permc_spec="COLAMD")
                prec = first.solve
            else:
                factor = la.cholesky_banded(pb.band(w), lower=True)
                prec = lambda r, f=factor: la.cho_solve_banded((f, True), r)
                if coarse is not None:
                    prec = _balanced(prec, H, coarse)
            delta, cg = pcg(H, -grad, prec, eta)
        cg_total += cg
        if delta @ true_grad >= 0:  # not a descent direction
            break
        jd, ad = J @ delta, A @ delta
        t = exact_line_search(jar, jd, d, delta @ ad, delta @ am)
        a += t * delta
        am += t * ad
        jar += t * jd
        if np.abs(t * delta).max() <= tol * (np.abs(a).max() + 1e-300):
            break
    return a, it, cg_total


def _coarse_basis(n: int, segment: int):
    """Piecewise-linear motions of each cable (pile.PileCase's 41 vertices) on knots
    ``segment`` vertices apart, (n, 3 knots)."""
    v_per = 41
    rows, cols, vals, col = [], [], [], 0
    for rod in range(n // (3 * v_per)):
        knots = list(range(0, v_per, segment)) + ([v_per - 1] if (v_per - 1) % segment else [])
        for v in range(v_per):
            k = max(i for i in range(len(knots) - 1) if knots[i] <= v)
            t = (v - knots[k]) / (knots[k + 1] - knots[k])
            for wgt, kn in ((1.0 - t, k), (t, k + 1)):
                for ax in range(3):
                    rows.append(3 * (v_per * rod + v) + ax), cols.append(3 * (col + kn) + ax), vals.append(wgt)
        col += len(knots)
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, 3 * col))


def _balanced(prec, H, P):
    """The balanced two-level preconditioner (I - QH) B^-1 (I - HQ) + Q, Q = P (P^T H P)^-1 P^T."""
    factor = la.cho_factor((P.T @ H @ P).toarray())

    def apply(r):
        q = P @ la.cho_solve(factor, P.T @ r)
        y = prec(r - H @ q)
        return y - P @ la.cho_solve(factor, P.T @ (H @ y)) + q
    return apply


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cables", type=int, default=100)
    ap.add_argument("--steps", default="61,62,119,120", help="steps at which to catch the problem (1/120 s each)")
    ap.add_argument("--segment", type=int, default=5, help="coarse knots this many vertices apart")
    args = ap.parse_args()
    steps = sorted(int(s) for s in args.steps.split(","))
    world = pile.build(pile.PileCase(cables=args.cables, seconds=1.0))
    caught = catch(world, steps)
    last = None
    for k in steps:
        pb = Problem(caught[k])
        print(f"step {k}: {pb.n} dofs, {len(pb.aref)} rows ({pb.kb} banded, {len(pb.aref) - pb.kb} far)")
        a, it, cg = newton(pb, "band-cg")
        active = pb.J @ a - pb.aref < 0
        print(f"  band-cg (derods): {it} Newton iterations, {cg} CG")
        for tol in (1e-8, 1e-6, 1e-4, 1e-3):
            b, it_t, cg_t = newton(pb, "band-cg", tol=tol)
            print(f"    to {tol:g}: {it_t} Newton, {cg_t} CG; accelerations off by {np.abs(b - a).max():.2e} m/s^2 "
                  f"({np.abs(b - a).max() / np.abs(a).max():.1e} of the largest)")
        print(f"  exact directions: {newton(pb, 'exact')[1]} Newton iterations")
        _, it_l, cg_l = newton(pb, "lagged")
        print(f"  lagged exact factor: {it_l} Newton, {cg_l} CG")
        _, it_c, cg_c = newton(pb, "coarse", segment=args.segment)
        print(f"  band + coarse ({args.segment}-vertex segments): {it_c} Newton, {cg_c} CG")
        H = pb.hessian(np.where(active, pb.d, 0.0)).tocsc()
        t = time.perf_counter()
        lu = sla.splu(H, permc_spec="COLAMD")
        print(f"  a sparse LU of H: {1e3 * (time.perf_counter() - t):.0f} ms, {lu.L.nnz + lu.U.nnz} nonzeros "
              f"(H: {H.nnz})")
        keys = pb.keys()
        if last is not None and last[0] == k - 1:
            before = dict(zip(last[1], last[2]))
            found = np.array([key in before for key in keys])
            at_a0 = pb.J @ pb.a0 - pb.aref < 0
            guess = np.where(found, [before.get(key, False) for key in keys], at_a0)
            print(f"  rows found at the last step {found.mean():.1%}; active set as at the solution: "
                  f"the last step's {np.mean(guess == active):.1%}, a0's {np.mean(at_a0 == active):.1%}")
            print(f"  from the last step's active set: {newton(pb, 'exact', guess=guess)[1]} Newton iterations "
                  f"(exact directions)")
        last = (k, keys, active)


if __name__ == "__main__":
    main()
