"""The comparison harness: benchmark cases (:mod:`.cases`) run on any backend (derods or
MuJoCo's native rods, :mod:`.native`), sweeps (:mod:`.sweep`) and the report (:mod:`.report`).

``from derods import bench; bench.run("cantilever", bench.CaseParams(n_edges=20))``.
"""

from .cases import (BACKEND_CASES, BACKENDS, CASES, MJCF_DIR, RUNNERS, CaseParams, cantilever, circle,  # noqa: F401
                    drop, environment, extreme, format_record, frequency, main, michell, params_from_args,
                    ring_buckles, run, stability, twist, twister_world)
