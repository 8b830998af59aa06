"""The comparison harness: benchmark cases (:mod:`.cases`, :mod:`.extreme`, :mod:`.coupling`)
with their parameters (:mod:`.params`) and measures (:mod:`.measures`), run on any backend
(derods or MuJoCo's native rods, :mod:`.native` and :mod:`.cable`) through one protocol (:mod:`.backends`),
by name (:mod:`.command`), in sweeps (:mod:`.sweep`) and into the report (:mod:`.report`).

``from derods import bench; bench.run("cantilever", bench.CaseParams(n_edges=20))``.
"""

from .backends import RodSimulator
from .cases import (cantilever, circle, drop, frequency, michell, oscillation, ring_buckles, stability, twist,
                    twister_world)
from .command import RUNNERS, environment, format_record, main, params_from_args, run
from .extreme import extreme
from .measures import swing_amplitudes
from .params import BACKEND_CASES, BACKENDS, CASES, CaseParams

__all__ = ["BACKEND_CASES", "BACKENDS", "CASES", "RUNNERS", "CaseParams", "RodSimulator", "cantilever",
           "circle", "drop", "environment", "extreme", "format_record", "frequency", "main", "michell",
           "oscillation", "params_from_args", "ring_buckles", "run", "stability", "swing_amplitudes", "twist",
           "twister_world"]
