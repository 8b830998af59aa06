"""Compiled (numba) kernels, split by concern: one rod step (:mod:`.step`), banded
linear algebra (:mod:`.banded`) and the contact rows (:mod:`.contact_rows`). Each
mirrors a numpy path that the tests hold it to."""
