"""Pure numerics of acs-twin: the spacecraft plant, onboard ACS algorithms and the batch engine.

No I/O, no web, no database (DESIGN.md). SI units inside; quaternions scalar-first Hamilton.
"""

from pathlib import Path as _Path

from sim_core.compiled_cache import guard as _guard_compiled_cache

_guard_compiled_cache(_Path(__file__).parent)  # a module's numba cache never outlives a change of its sources
