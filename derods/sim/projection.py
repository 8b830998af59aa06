"""Fast projection onto inextensible edges (Goldenthal et al. 2007, Algorithm 1).

The inextensibility method of the DER paper (Bergou et al. 2008, section 6):
after an unconstrained step, positions are projected back onto the manifold
of constant edge lengths, C_j(x) = |e^j|^2 / |ebar^j| - |ebar^j| = 0, by
repeated mass-weighted least-norm corrections

    G dlambda = C,  G = grad C  M^-1  grad C^T,   x <- x - M^-1 grad C^T dlambda,

until every edge strain is below the tolerance. For an open rod G is
tridiagonal (neighbouring edges share a vertex), so each iteration is one
banded solve. derods offers it as ``World(mode="projection")`` beside the
stiff stretching term of the implicit mode, so the two can be weighed; the step
runs it compiled (:mod:`derods._numba.projection`) with the tolerance below.
"""

from __future__ import annotations

#: Tolerance [relative edge strain] and iteration cap of every projection of a step (the
#: projection mode's, the strain limit's).
PROJECTION_TOL = 1e-10
PROJECTION_MAX_ITER = 50
