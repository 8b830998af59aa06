"""Which of a contact solve's rows make up each elliptic cone, compiled: MuJoCo's contacts
as the stage reads them, each elliptic contact's rows split as one group, the solve's
:class:`derods._numba.cones.Cones`, and one far-row pattern per cone (so that the cone's
virtual rows, :func:`derods._numba.cones.write_virtual`, are combinations of rows that
share their columns). The cones' cost is :mod:`derods._numba.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .cones import Cones


class ConeContacts(NamedTuple):
    """MuJoCo's contacts, as a contact stage finds its elliptic cones: elliptic, MuJoCo's
    constraint type of elliptic contact rows; efc_id (nefc,), each row's contact; per
    contact (ncon) its first row adr, dim, mu, friction (ncon, 5) and dist [m] (MuJoCo's
    signed distance: > 0 for a speculative contact, within a margin). Empty arrays: no
    contact this step. A model without elliptic cones passes None instead (compiled
    without them: five arrays less to hand over on every contact step)."""

    elliptic: int
    efc_id: np.ndarray
    adr: np.ndarray
    dim: np.ndarray
    mu: np.ndarray
    friction: np.ndarray
    dist: np.ndarray


@nb.njit(cache=True)
def share_patterns(fptr, fcol, fval, kb, cones):
    """The far rows (CSR fptr, fcol, fval; the solve's rows past kb) with each far cone's
    rows over the union of their columns (zeros where a row has none), so that their
    combinations (:func:`write_virtual`) keep one pattern. Returns (fptr, fcol, fval)."""
    kf = len(fptr) - 1
    owner = np.full(kf, -1, dtype=np.int64)
    for c in range(len(cones.dim)):
        if cones.rows[c, 0] >= kb:
            for j in range(cones.dim[c]):
                owner[cones.rows[c, j] - kb] = c
    cols_of = []
    for c in range(len(cones.dim)):
        if cones.rows[c, 0] < kb:
            cols_of.append(np.zeros(0, dtype=np.int64))
            continue
        total = 0
        for j in range(cones.dim[c]):
            r = cones.rows[c, j] - kb
            total += fptr[r + 1] - fptr[r]
        allc = np.empty(total, dtype=np.int64)
        q = 0
        for j in range(cones.dim[c]):
            r = cones.rows[c, j] - kb
            for p in range(fptr[r], fptr[r + 1]):
                allc[q] = fcol[p]
                q += 1
        cols_of.append(np.unique(allc))
    nptr = np.zeros(kf + 1, dtype=np.int64)
    for r in range(kf):
        nptr[r + 1] = nptr[r] + (len(cols_of[owner[r]]) if owner[r] >= 0 else fptr[r + 1] - fptr[r])
    ncol = np.empty(nptr[kf], dtype=np.int64)
    nval = np.zeros(nptr[kf])
    for r in range(kf):
        if owner[r] < 0:
            for p in range(fptr[r], fptr[r + 1]):
                ncol[nptr[r] + p - fptr[r]] = fcol[p]
                nval[nptr[r] + p - fptr[r]] = fval[p]
            continue
        cols = cols_of[owner[r]]
        for x in range(len(cols)):
            ncol[nptr[r] + x] = cols[x]
        for p in range(fptr[r], fptr[r + 1]):
            x = np.searchsorted(cols, fcol[p])
            nval[nptr[r] + x] = fval[p]
    return nptr, ncol, nval


@nb.njit(cache=True)
def cone_groups(efc_rows, efc_type, cone_contacts):
    """Each of a block's rows' group (:func:`derods._numba.row_split.split_bordered_rows`):
    an elliptic contact's rows (efc_rows (k,): their numbers among MuJoCo's rows, each
    contact's consecutive) the block number of its first, every other row its own; empty
    if there is no elliptic contact (cone_contacts None or empty)."""
    k = len(efc_rows)
    if cone_contacts is None:
        return np.zeros(0, dtype=np.int64)
    if len(cone_contacts.adr) == 0:
        return np.zeros(0, dtype=np.int64)
    group = np.arange(k)
    for b in range(k):
        e = efc_rows[b]
        if efc_type[e] == cone_contacts.elliptic:
            first = cone_contacts.adr[cone_contacts.efc_id[e]]
            group[b] = b - (e - first)
    return group


@nb.njit(cache=True)
def block_cones(efc, efc_rows, efc_type, group, cone_contacts):
    """The elliptic cones among a block's solved rows (:class:`derods._numba.cones.Cones`,
    rows in the solve's order): efc (k,), the solved rows' block numbers; efc_rows,
    efc_type, group: as :func:`cone_groups`. A speculative contact (within a margin, not
    yet touching) gets no friction: its cone is its normal row alone, which only keeps the
    rod from crossing the surface by the step's end (with its frictional rows it could
    push and brake a rod sliding a hair above a floor)."""
    if cone_contacts is None:
        return Cones(group.reshape((0, 6)), group, np.zeros(0), np.zeros((0, 5)))
    if len(group) == 0:
        return Cones(group.reshape((0, 6)), group, np.zeros(0), np.zeros((0, 5)))
    at = np.full(len(group), -1, dtype=np.int64)
    for i in range(len(efc)):
        at[efc[i]] = i
    nc = 0
    for i in range(len(efc)):
        b = efc[i]
        if group[b] == b and _is_cone(efc_rows[b], efc_type, cone_contacts):
            nc += 1
    rows = np.full((nc, 6), -1, dtype=np.int64)
    dim = np.zeros(nc, dtype=np.int64)
    mu = np.zeros(nc)
    friction = np.zeros((nc, 5))
    c = 0
    for i in range(len(efc)):
        b = efc[i]
        if not (group[b] == b and _is_cone(efc_rows[b], efc_type, cone_contacts)):
            continue
        con = cone_contacts.efc_id[efc_rows[b]]
        dim[c] = cone_contacts.dim[con]
        mu[c] = cone_contacts.mu[con]
        if cone_contacts.dist[con] <= 0.0:  # touching; a speculative contact has no friction
            friction[c] = cone_contacts.friction[con]
        for j in range(dim[c]):
            rows[c, j] = at[b + j]
        c += 1
    return Cones(rows, dim, mu, friction)


@nb.njit(cache=True)
def _is_cone(e, efc_type, cone_contacts):
    """Whether MuJoCo's row e is the first of an elliptic contact."""
    return efc_type[e] == cone_contacts.elliptic and cone_contacts.adr[cone_contacts.efc_id[e]] == e
