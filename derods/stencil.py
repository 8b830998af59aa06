"""Assembly of per-stencil derivatives into rod-wide gradients and Hessians.

Each energy term is a sum over *stencils*: edges (stretch, two vertices) and
joints (bend and twist, three vertices plus the twist angles of the two edges).
Terms return their derivatives per stencil; this module adds them up.

Degrees of freedom: vertex coordinates, ordered ``3 * vertex + axis``
(n_x = 3 n_vertices), followed by the twist angles theta of the edges
(n_theta = n_edges). Within a joint stencil the order is x_prev, x_joint,
x_next (9 entries) then theta_prev, theta_next (2 entries).

The x-x Hessian of an open rod is banded with 8 sub-diagonals and is returned
in the *lower* form of :func:`scipy.linalg.solveh_banded` /
:func:`scipy.linalg.cholesky_banded` (``lower=True``): ``ab[i - j, j] = H[i, j]``
for ``i >= j``. Banded blocks of many rods laid end to end along the last
axis form the block-diagonal matrix of all rods, so one banded solve serves
them all. A closed rod couples its last vertices to its first ones, which no
banded form holds; use :meth:`Hessian.xx_sparse` there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import joint_vertex_index

#: Sub-diagonals of the x-x Hessian of an open rod (a joint couples vertices k-1..k+1).
XX_BANDWIDTH = 8
#: Sub-diagonals of a ring's x-x Hessian in :func:`ring_order` (a joint's vertices lie
#: within 4 places of each other there).
RING_BANDWIDTH = 14


def ring_order(n_vertices: int) -> np.ndarray:
    """Vertex order 0, n-1, 1, n-2, 2, ... that makes a ring's Hessian banded.

    In natural order a ring couples its last vertices to its first ones, which
    no band holds; zig-zagging from both ends puts every ring neighbour within
    two places, so the Hessian has :data:`RING_BANDWIDTH` sub-diagonals.
    """
    head = np.arange((n_vertices + 1) // 2)
    tail = n_vertices - 1 - np.arange(n_vertices // 2)
    out = np.empty(n_vertices, dtype=int)
    out[0::2] = head
    out[1::2] = tail
    return out


def scatter_joint_x(g: np.ndarray, n_vertices: int, closed: bool) -> np.ndarray:
    """Sum joint-stencil vectors onto vertices: g (..., n_joints, 3, 3) -> (..., n_vertices, 3)."""
    if closed:
        return np.roll(g[..., 0, :], -1, axis=-2) + g[..., 1, :] + np.roll(g[..., 2, :], 1, axis=-2)
    out = np.zeros(g.shape[:-3] + (n_vertices, 3))
    out[..., :-2, :] += g[..., 0, :]
    out[..., 1:-1, :] += g[..., 1, :]
    out[..., 2:, :] += g[..., 2, :]
    return out


def scatter_edge_x(g: np.ndarray, n_vertices: int, closed: bool) -> np.ndarray:
    """Sum edge-stencil vectors onto vertices: g (..., n_edges, 2, 3) -> (..., n_vertices, 3)."""
    if closed:
        return g[..., 0, :] + np.roll(g[..., 1, :], 1, axis=-2)
    out = np.zeros(g.shape[:-3] + (n_vertices, 3))
    out[..., :-1, :] += g[..., 0, :]
    out[..., 1:, :] += g[..., 1, :]
    return out


def scatter_joint_theta(g: np.ndarray, n_edges: int, closed: bool) -> np.ndarray:
    """Sum joint-stencil twist-angle entries onto edges: (..., n_joints, 2) -> (..., n_edges)."""
    if closed:
        return np.roll(g[..., 0], -1, axis=-1) + g[..., 1]
    out = np.zeros(g.shape[:-2] + (n_edges,))
    out[..., :-1] += g[..., 0]
    out[..., 1:] += g[..., 1]
    return out


def add_optional(a, b):
    """a + b where either may be None (a term that does not produce that block)."""
    if a is None:
        return b
    if b is None:
        return a
    return a + b


@dataclass
class Hessian:
    """Second derivatives of a rod energy, kept per stencil.

    Any block may be None when the term does not produce it.

    * ``edge_xx``: (..., n_edges, 6, 6), over (x_j, x_{j+1}) [N/m].
    * ``joint_xx``: (..., n_joints, 9, 9), over (x_prev, x_joint, x_next) [N/m].
    * ``joint_xt``: (..., n_joints, 9, 2), x against (theta_prev, theta_next) [N/rad].
    * ``joint_tt``: (..., n_joints, 2, 2), over (theta_prev, theta_next) [N m/rad^2].
    """

    n_vertices: int
    closed: bool
    edge_xx: np.ndarray | None = None
    joint_xx: np.ndarray | None = None
    joint_xt: np.ndarray | None = None
    joint_tt: np.ndarray | None = None

    def __add__(self, other: "Hessian") -> "Hessian":
        add = add_optional
        return Hessian(
            self.n_vertices,
            self.closed,
            add(self.edge_xx, other.edge_xx),
            add(self.joint_xx, other.joint_xx),
            add(self.joint_xt, other.joint_xt),
            add(self.joint_tt, other.joint_tt),
        )

    @property
    def n_edges(self) -> int:
        return self.n_vertices if self.closed else self.n_vertices - 1

    def _joint_dofs(self) -> tuple[np.ndarray, np.ndarray]:
        """x dof indices (n_joints, 9) and theta dof indices (n_joints, 2) of each joint."""
        v = joint_vertex_index(self.n_vertices, self.closed)
        xd = (3 * v[:, :, None] + np.arange(3)).reshape(-1, 9)
        ne = self.n_edges
        k = np.arange(v.shape[0])
        if self.closed:
            td = np.stack([(k - 1) % ne, k], axis=1)
        else:
            td = np.stack([k, k + 1], axis=1)
        return xd, 3 * self.n_vertices + td

    def _edge_dofs(self) -> np.ndarray:
        j = np.arange(self.n_edges)
        v = np.stack([j, (j + 1) % self.n_vertices], axis=1)
        return (3 * v[:, :, None] + np.arange(3)).reshape(-1, 6)

    def dense(self) -> np.ndarray:
        """Full symmetric matrix over (x, theta), shape (..., n_x + n_theta, n_x + n_theta).

        Meant for tests and small rods; use the banded or sparse forms to solve.
        """
        nd = 3 * self.n_vertices + self.n_edges
        batch = next(b.shape[:-3] for b in (self.edge_xx, self.joint_xx, self.joint_tt) if b is not None)
        out = np.zeros(batch + (nd, nd))
        if self.edge_xx is not None:
            d = self._edge_dofs()
            np.add.at(out, (..., d[:, :, None], d[:, None, :]), self.edge_xx)
        xd, td = self._joint_dofs()
        if self.joint_xx is not None:
            np.add.at(out, (..., xd[:, :, None], xd[:, None, :]), self.joint_xx)
        if self.joint_xt is not None:
            np.add.at(out, (..., xd[:, :, None], td[:, None, :]), self.joint_xt)
            np.add.at(out, (..., td[:, :, None], xd[:, None, :]), np.swapaxes(self.joint_xt, -1, -2))
        if self.joint_tt is not None:
            np.add.at(out, (..., td[:, :, None], td[:, None, :]), self.joint_tt)
        return out

    def xx_banded(self) -> np.ndarray:
        """x-x block of an open rod in lower banded form, shape (..., 9, 3 n_vertices).

        ``ab[d, c] = H[c + d, c]``; pass to ``scipy.linalg.solveh_banded(ab, b, lower=True)``.
        """
        if self.closed:
            raise ValueError("a closed rod's Hessian is not banded; use xx_sparse()")
        nv = self.n_vertices
        bw = XX_BANDWIDTH + 1
        batch = next(b.shape[:-3] for b in (self.edge_xx, self.joint_xx) if b is not None)
        ab = np.zeros(batch + (bw, 3 * nv))
        if self.joint_xx is not None:
            _add_lower_band(ab, self.joint_xx, 9, n_stencils=nv - 2)
        if self.edge_xx is not None:
            _add_lower_band(ab, self.edge_xx, 6, n_stencils=nv - 1)
        return ab

    def xx_banded_ordered(self, order: np.ndarray, bandwidth: int) -> np.ndarray:
        """x-x block in lower banded form with the vertices taken in ``order`` (one rod).

        order: vertex indices in the order of the rows, shape (n_vertices,), e.g.
        :func:`ring_order` for a ring. bandwidth: sub-diagonals to keep; an entry
        outside them raises ValueError. Returns shape (bandwidth + 1, 3 n_vertices).
        """
        position = np.empty(self.n_vertices, dtype=int)
        position[order] = np.arange(self.n_vertices)
        n = 3 * self.n_vertices
        ab = np.zeros((bandwidth + 1) * n)
        blocks = []
        if self.edge_xx is not None:
            blocks.append((self._edge_dofs(), self.edge_xx))
        if self.joint_xx is not None:
            blocks.append((self._joint_dofs()[0], self.joint_xx))
        for dofs, vals in blocks:
            pd = 3 * position[dofs // 3] + dofs % 3  # permuted dof of every stencil entry
            rows = np.broadcast_to(pd[:, :, None], vals.shape)
            cols = np.broadcast_to(pd[:, None, :], vals.shape)
            lower = rows >= cols
            d = (rows - cols)[lower]
            if d.size and d.max() > bandwidth:
                raise ValueError(f"an entry lies {d.max()} below the diagonal, beyond bandwidth {bandwidth}")
            np.add.at(ab, d * n + cols[lower], vals[lower])
        return ab.reshape(bandwidth + 1, n)

    def xx_sparse(self):
        """x-x block as a scipy.sparse CSR matrix (one rod, no batch dimensions)."""
        import scipy.sparse as sp

        rows, cols, vals = [], [], []
        if self.edge_xx is not None:
            d = self._edge_dofs()
            rows.append(np.broadcast_to(d[:, :, None], self.edge_xx.shape).ravel())
            cols.append(np.broadcast_to(d[:, None, :], self.edge_xx.shape).ravel())
            vals.append(self.edge_xx.ravel())
        if self.joint_xx is not None:
            xd, _ = self._joint_dofs()
            rows.append(np.broadcast_to(xd[:, :, None], self.joint_xx.shape).ravel())
            cols.append(np.broadcast_to(xd[:, None, :], self.joint_xx.shape).ravel())
            vals.append(self.joint_xx.ravel())
        n = 3 * self.n_vertices
        return sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
        )


# Lower-band gather tables: for a stencil block of size k starting at dof 3*s,
# entry (p, q) with p >= q lands in ab[p - q, 3*s + q].
_BAND_TABLES: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _band_table(k: int) -> tuple[np.ndarray, np.ndarray]:
    if k not in _BAND_TABLES:
        d = np.arange(XX_BANDWIDTH + 1)[:, None]
        q = np.arange(k)[None, :]
        p = q + d
        valid = p < k
        _BAND_TABLES[k] = (np.where(valid, p * k + q, 0), valid.astype(float))
    return _BAND_TABLES[k]


def _add_lower_band(ab: np.ndarray, blocks: np.ndarray, k: int, n_stencils: int) -> None:
    """Add stencil blocks (..., n_stencils, k, k), stencil s at dofs 3s..3s+k-1, to ab."""
    idx, valid = _band_table(k)
    flat = blocks.reshape(blocks.shape[:-2] + (k * k,))
    contrib = flat[..., idx] * valid  # (..., n_stencils, 9, k): [d, q]
    nb = k // 3
    for jv in range(nb):
        # Columns 3 s + q with q = 3 jv + c belong to vertex s + jv.
        ab_view = ab.reshape(ab.shape[:-1] + (-1, 3))
        seg = contrib[..., 3 * jv : 3 * jv + 3]  # (..., n_stencils, 9, 3)
        ab_view[..., :, jv : jv + n_stencils, :] += np.moveaxis(seg, -3, -2)
