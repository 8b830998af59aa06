"""The comparison harness: benchmark cases (:mod:`.cases`) run on any backend (derods or
MuJoCo's native rods, :mod:`.native`) through one protocol (:mod:`.backends`), sweeps
(:mod:`.sweep`) and the report (:mod:`.report`).

``from derods import bench; bench.run("cantilever", bench.CaseParams(n_edges=20))``.
"""

from .backends import RodSimulator
from .cases import (BACKEND_CASES, BACKENDS, CASES, RUNNERS, CaseParams, cantilever, circle, drop,
                    environment, extreme, format_record, frequency, main, michell, oscillation, params_from_args,
                    ring_buckles, run, stability, swing_amplitudes, twist, twister_world)

__all__ = ["BACKEND_CASES", "BACKENDS", "CASES", "RUNNERS", "CaseParams", "RodSimulator", "cantilever",
           "circle", "drop", "environment", "extreme", "format_record", "frequency", "main", "michell",
           "oscillation", "params_from_args", "ring_buckles", "run", "stability", "swing_amplitudes", "twist",
           "twister_world"]
