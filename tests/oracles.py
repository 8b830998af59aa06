"""Reference forms of the step's algebra that only the tests use.

The package runs these pieces inside compiled calls (one per step); the tests take them
apart: the banded algebra in scipy's layout (derods/_numba/banded.py), the implicit
system built from per-rod blocks with its products (derods/sim/implicit.py), contact rows
as an object with their Newton solve (derods/sim/contact.py) and the fast projection of
one rod (derods/sim/projection.py). Each calls the package's own kernels, so what it
checks is the code a World runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from derods._numba import contact_newton as _newton
from derods._numba import contact_rows as _rows
from derods._numba import implicit as _implicit
from derods._numba.banded import cholesky_into, inverse_band, matvec_into, solve_columns
from derods._numba.projection import project_rod
from derods.sim.contact import MAX_ITER, TOL
from derods.sim.implicit import ImplicitSystem
from derods.stencil import XX_BANDWIDTH


# -- banded algebra in scipy's layout (lower band ab[d, j] = A[j + d, j], shape (b + 1, n)) --

def band_cholesky(ab: np.ndarray) -> np.ndarray:
    """Lower banded Cholesky factor of ab (b + 1, n), in scipy's layout (b + 1, n), as
    :func:`scipy.linalg.cholesky_banded` with ``lower=True`` returns it."""
    lt = np.empty((ab.shape[1], ab.shape[0]))
    cholesky_into(ab, lt)
    return lt.T.copy()


def band_solve(lb: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve L L^T x = rhs for a lower banded factor lb (b + 1, n) in scipy's layout;
    rhs shape (n, m)."""
    x = rhs.copy()
    solve_columns(lb.T.copy(), x, 0, x.shape[0], 0)
    return x


def banded_inverse_band(lb: np.ndarray) -> np.ndarray:
    """The entries of A^-1 inside the band of A (b + 1, n), from its factor lb in scipy's
    layout (see :func:`derods._numba.banded.inverse_band`)."""
    return inverse_band(lb.T.copy(), lb.shape[0])


def band_matvec(ab: np.ndarray, w: np.ndarray) -> np.ndarray:
    """y = A w for symmetric A in lower banded form (b + 1, n); w shape (n,)."""
    y = np.empty(ab.shape[1])
    matvec_into(ab, w, y)
    return y


def restrict_band(ab: np.ndarray, start: int, stop: int) -> np.ndarray:
    """The band of the sub-matrix H[start:stop, start:stop] (dof indices), a copy."""
    sub = ab[:, start:stop].copy()
    n = stop - start
    for d in range(1, sub.shape[0]):
        sub[d, max(n - d, 0):] = 0.0
    return sub


# -- the implicit system A = M (1 + h a_m) + (h^2 + h b) K (derods/sim/implicit.py) ----------

def implicit_system(h: float, offsets: np.ndarray, bands: list[np.ndarray],
                    rank1: list[tuple[np.ndarray, float] | None], mass: np.ndarray,
                    mass_damping: float = 0.0, stiffness_damping: float = 0.0) -> ImplicitSystem:
    """A factored system from per-rod pieces: offsets (n_rods + 1,) of each rod's dofs;
    bands, each rod's lower band (k_i, n_i) [N/m]; rank1, per rod (g [1/m], c [N m]) or None."""
    rows = max([XX_BANDWIDTH + 1] + [b.shape[0] for b in bands])
    tw = [i for i, r in enumerate(rank1) if r is not None and r[1] != 0.0]
    system = ImplicitSystem(h, int(offsets[-1]), mass, mass_damping, stiffness_damping, rows,
                            [offsets[i] for i in tw], [offsets[i + 1] for i in tw])
    for i, band in enumerate(bands):
        system.k_band[: band.shape[0], offsets[i]:offsets[i + 1]] = band
    for k, i in enumerate(tw):
        system.g[offsets[i]:offsets[i + 1]] = rank1[i][0]
        system.tw_c[k] = rank1[i][1]
    _implicit.factor_system(system.arrays, system.m_coef, system.s)
    return system


def k_matvec(system: ImplicitSystem, w: np.ndarray) -> np.ndarray:
    """K w, w shape (n,)."""
    y = np.empty(system.n)
    _implicit.k_matvec_into(system.arrays, np.ascontiguousarray(w, dtype=float), y)
    return y


def a_matvec(system: ImplicitSystem, w: np.ndarray) -> np.ndarray:
    """A w, w shape (n,)."""
    return system.s * k_matvec(system, w) + system.mass * system.m_coef * w


def implicit_rhs(system: ImplicitSystem, force: np.ndarray, v: np.ndarray) -> np.ndarray:
    """r = F - a_m M v - (b + h) K v [N]."""
    return (force - system.mass_damping * system.mass * v
            - (system.stiffness_damping + system.h) * k_matvec(system, v))


def inverse_diagonal_terms(system: ImplicitSystem) -> tuple[np.ndarray, list[tuple[np.ndarray, float]]]:
    """What the entries of A^-1 near the diagonal need: (zb, corrections), zb the band of
    B^-1, B the banded part of A (Takahashi's recurrence on its factor); corrections a list
    of (z, w) with A^-1 = B^-1 - sum w z z^T (Sherman-Morrison for the rank-one twist terms)."""
    corrections = []
    for i in range(len(system.tw_lo)):
        z = np.zeros(system.n)
        lo, hi = system.tw_lo[i], system.tw_hi[i]
        z[lo:hi] = system.z[lo:hi]
        corrections.append((z, system.s * system.tw_c[i] / system.den[i]))
    return inverse_band(system.lt, system.lt.shape[1]), corrections


def random_band(rng: np.random.Generator, m: int) -> np.ndarray:
    """Lower band (9, m) of a random symmetric matrix made positive definite (the band of
    a a^T, a with entries N(0, 0.3^2), plus 5 on the diagonal): a stiffness band for
    tests of the solves (its Cholesky factor exists, its entries are all of one scale)."""
    a = rng.normal(size=(m, m)) * 0.3
    full = a @ a.T
    band = np.zeros((9, m))
    for d in range(9):
        band[d, : m - d] = np.diag(full, -d)
    band[0] += 5.0
    return band


# -- contact rows and their Newton solve (derods/sim/contact.py) -----------------------------

@dataclass
class ContactRows:
    """Constraint rows as derods solves them.

    Most rows touch one or two neighbouring vertices and fit a window of 9 dofs
    ("banded" rows: ``col0``, ``jw``); a self-contact between distant parts of a
    rod does not ("far" rows: ``jf``), and enters the Newton step as a low-rank
    update. Per row, banded rows first, then far rows:

    aref: reference acceleration [m/s^2], shape (k,). d: row weight 1/R, shape (k,).
    efc: the rows' indices in MuJoCo's efc arrays, shape (k,).
    col0: first local dof of each banded row's window, shape (k_b,), int64.
    jw: banded rows' Jacobian entries in their windows, shape (k_b, 9).
    jf: far rows' Jacobians over all local dofs, shape (k_f, n) (k_f may be 0).
    """

    col0: np.ndarray
    jw: np.ndarray
    aref: np.ndarray
    d: np.ndarray
    efc: np.ndarray
    jf: np.ndarray | None = None

    def __post_init__(self):
        if self.jf is None:
            self.jf = np.zeros((0, 0))

    def __len__(self) -> int:
        return len(self.efc)

    @property
    def n_banded(self) -> int:
        return len(self.col0)

    def far_csr(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The far rows as CSR (row pointers, columns, values), for n local dofs."""
        return _rows.far_rows_csr(self.jf if self.jf.shape[0] else np.zeros((0, n)))

    def rows(self, n: int) -> _rows.Rows:
        """The rows as the compiled products take them, for n local dofs."""
        return _rows.Rows(self.col0, self.jw, *self.far_csr(n))

    def apply(self, a: np.ndarray) -> np.ndarray:
        """J a for every row, shape (k,)."""
        a = np.ascontiguousarray(a, dtype=float)
        return _rows.apply_all(self.rows(len(a)), a)

    def transpose_apply(self, lam: np.ndarray, n: int) -> np.ndarray:
        """J^T lam, shape (n,)."""
        return _rows.transpose_apply_all(self.rows(n), np.ascontiguousarray(lam, dtype=float), n)

    def band(self, weights: np.ndarray, n: int) -> np.ndarray:
        """Lower band (9, n) of J_b^T diag(weights) J_b over the banded rows."""
        return _rows.rows_band(self.col0, self.jw, np.ascontiguousarray(weights[: self.n_banded]), n)


def contact_solve(system: ImplicitSystem, a0: np.ndarray, rows: ContactRows, max_iter: int = MAX_ITER,
                  tol: float = TOL) -> tuple[np.ndarray, np.ndarray, int]:
    """Newton's method on the contact problem in the implicit metric, the compiled solve a
    World's contact stage runs (:func:`derods._numba.contact_newton.newton`, no border).

    system: a factored :class:`derods.sim.implicit.ImplicitSystem`.
    a0: unconstrained end-of-step acceleration [m/s^2], shape (n,).
    Returns (a [m/s^2] shape (n,), row forces lam [N] shape (k,), iterations).
    """
    a, _, lam, it = _newton.newton(system.arrays, np.ascontiguousarray(a0, dtype=float), rows.rows(system.n),
                                   np.ascontiguousarray(rows.aref, dtype=float),
                                   np.ascontiguousarray(rows.d, dtype=float), _newton.no_border(system.n, len(rows)),
                                   None, max_iter, tol)
    return a, lam, it


# -- fast projection of one open rod (derods/sim/projection.py) ------------------------------

def project(x: np.ndarray, inv_mass: np.ndarray, rest_len: np.ndarray, tol: float = 1e-10,
            max_iter: int = 50) -> tuple[np.ndarray, int]:
    """Project an open rod's vertices onto its rest edge lengths.

    x: vertex positions [m], shape (n_vertices, 3).
    inv_mass: inverse vertex masses [1/kg], shape (n_vertices,); 0 holds a vertex in place.
    rest_len: rest edge lengths [m], shape (n_edges,).
    tol: largest relative edge strain accepted.
    Returns (projected positions [m], iterations). Raises RuntimeError if it does not converge.
    """
    x = np.array(x, dtype=float)
    it = project_rod(x, np.ascontiguousarray(inv_mass, dtype=float), np.ascontiguousarray(rest_len, dtype=float),
                     tol, max_iter)
    if it < 0:
        e = np.diff(x, axis=0)
        strain = np.max(np.abs(np.einsum("ij,ij->i", e, e) / rest_len**2 - 1.0))
        raise RuntimeError(f"fast projection did not converge in {max_iter} iterations (strain {strain:.2e})")
    return x, it
