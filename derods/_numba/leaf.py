"""Kernels that only read and write the arrays they are handed, compiled without numba's
reference counts (:func:`leaf`).

numba counts the references to every array: a compiled function takes one on each array
argument when it starts (on every array of a bundle it is handed) and gives it back when it
returns, each an atomic increment or decrement of the array's shared count. On the
development VM such a pair costs ~7 ns, more than the arithmetic of a kernel called per
joint, edge or Newton iteration: the joint Hessian's addition, four arrays handed at each
of ten lying rods' 300 joints, took 17 of the 72 us of their elastic terms
(``rods_step`` in a compiled loop). A kernel that allocates nothing needs no counts:
:func:`leaf` compiles it without them (numba's NRT off for it; an allocation inside then
fails to compile instead of going uncounted). Its callers count as before.
"""

from __future__ import annotations

import numba as nb


def leaf(fn):
    """``numba.njit(cache=True)`` for a kernel that allocates no array (see the module)."""
    return nb.njit(cache=True, _nrt=False)(fn)
