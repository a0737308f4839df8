"""The numba signatures a run compiled, recorded from numba's cache index files and compiled again on demand.

``acs-twin warm`` flies what ``serve`` flies; the test suite (and the what-if, diagnosis and camera paths) call
further kernels, or the same ones with other argument types, which numba then compiles on first call — in each
pytest worker and Dask worker that meets them first, one core each, minutes in all on a loaded 2-core machine.
:func:`read_cache` reads every signature from the cache indexes (``<module>.<function>-<line>.py311.nbi``, each a
pickle of the cache stamp and a dict keyed by (argument types, target, ...)) of ``sim_core`` and ``telemetry``;
``kernel_signatures.json`` beside this module holds those a suite run compiled beyond what ``acs-twin warm``'s
flight compiles, and ``acs-twin warm --recorded`` compiles them (:func:`compile_recorded`) in a second process beside
the flight, both saving under a lock (:func:`serialise_cache_saves`), so that later processes only load machine
code. A record is only a list of what to compile: an entry whose function or types changed is skipped and named
(numba compiles at call time as ever), so a stale record costs time, never a result.

Regenerate it after kernels changed their signatures (on a quiet machine, about ten minutes)::

    NUMBA_CACHE_DIR=/tmp/w acs-twin warm && cp -a /tmp/w /tmp/s
    NUMBA_CACHE_DIR=/tmp/s python -m pytest -n 2 tests
    python -m backend.jobs.kernel_signatures /tmp/s --beyond /tmp/w

(tests/sim_core/test_compiled_cache.py expects the cache beside the sources and fails under ``NUMBA_CACHE_DIR``.)
"""

from __future__ import annotations

import importlib
import json
import os
import pickle
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, cast

__all__ = [
    "RECORD",
    "CompileReport",
    "beyond",
    "cache_folders",
    "compile_recorded",
    "compile_recorded_beside",
    "decode_type",
    "encode_type",
    "read_cache",
    "record",
    "serialise_cache_saves",
    "write",
]

RECORD = Path(__file__).with_name("kernel_signatures.json")
PACKAGES = ("sim_core", "telemetry")
SAVE_LOCK = ".acs-twin-save.lock"  # in each cache folder: numba's cache saves serialised across processes


def encode_type(t: Any) -> Any:
    """A numba argument type as JSON (arrays as ``float64[2d,C]``, ``bool[1d,A,readonly]``; scalars as ``float64``;
    literals, tuples, named tuples as objects); ValueError for others."""
    from numba.core import types

    if isinstance(t, types.Array):
        return f"{t.dtype}[{t.ndim}d,{t.layout}{'' if t.mutable else ',readonly'}]"  # e.g. float64[2d,C]
    if isinstance(t, types.Literal):
        return {"literal": t.literal_value}
    if isinstance(t, types.Boolean | types.Integer | types.Float):
        return str(t)
    if isinstance(t, types.NamedUniTuple):
        cls = f"{t.instance_class.__module__}:{t.instance_class.__qualname__}"
        return {"named_unituple": cls, "dtype": encode_type(t.dtype), "count": t.count}
    if isinstance(t, types.NamedTuple):
        cls = f"{t.instance_class.__module__}:{t.instance_class.__qualname__}"
        return {"named_tuple": cls, "fields": [encode_type(f) for f in t.types]}
    if isinstance(t, types.UniTuple):
        return {"unituple": encode_type(t.dtype), "count": t.count}
    if isinstance(t, types.Tuple):
        return {"tuple": [encode_type(f) for f in t.types]}
    raise ValueError(f"no JSON form for numba type {t!r}")


def _scalar(name: str) -> Any:
    import numpy as np
    from numba.np.numpy_support import from_dtype

    return from_dtype(np.dtype(name))


def _class(ref: str) -> type:
    module, _, qualname = ref.partition(":")
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj  # type: ignore[no-any-return]


def decode_type(value: Any) -> Any:
    """The numba type :func:`encode_type` wrote (ValueError, ImportError or AttributeError if it is gone)."""
    from numba.core import types

    if isinstance(value, str) and "[" in value:
        dtype, _, shape = value.rstrip("]").partition("[")
        ndim, layout, *readonly = shape.split(",")
        if layout not in ("C", "F", "A"):
            raise ValueError(f"unknown array layout in {value!r}")
        order = cast(Literal["C", "F", "A"], layout)
        return types.Array(_scalar(dtype), int(ndim.rstrip("d")), order, readonly=readonly == ["readonly"])
    if isinstance(value, str):
        return _scalar(value)
    if "literal" in value:
        return types.literal(value["literal"])
    if "named_unituple" in value:
        return types.NamedUniTuple(decode_type(value["dtype"]), value["count"], _class(value["named_unituple"]))
    if "named_tuple" in value:
        return types.NamedTuple([decode_type(f) for f in value["fields"]], _class(value["named_tuple"]))
    if "unituple" in value:
        return types.UniTuple(decode_type(value["unituple"]), value["count"])
    if "tuple" in value:
        return types.Tuple([decode_type(f) for f in value["tuple"]])
    raise ValueError(f"unknown recorded type {value!r}")


def read_cache(cache_dirs: dict[str, list[Path]]) -> dict[str, dict[str, list[list[Any]]]]:
    """Per ``package.module``, per function name: the encoded argument types of every signature in the cache
    indexes under ``cache_dirs`` (package -> its cache folders), sorted; functions nested in others are left out."""
    found: dict[str, dict[str, set[str]]] = {}
    for package, dirs in cache_dirs.items():
        for d in dirs:
            for index in sorted(d.glob("*.nbi")):
                stem = index.name.split("-")[0]  # <module>.<qualname>-<line>.py<ver>.nbi
                module, _, function = stem.partition(".")
                if not function or "." in function:
                    continue
                with index.open("rb") as f:
                    pickle.load(f)  # numba's version
                    _stamp, overloads = pickle.loads(f.read())
                for key in overloads:
                    try:
                        sig = json.dumps([encode_type(t) for t in key[0]], sort_keys=True)
                    except ValueError as exc:
                        print(f"kernel_signatures: {package}.{module}.{function} left out: {exc}", file=sys.stderr)
                        continue
                    found.setdefault(f"{package}.{module}", {}).setdefault(function, set()).add(sig)
    return {
        m: {fn: [json.loads(s) for s in sorted(sigs)] for fn, sigs in sorted(fns.items())}
        for m, fns in sorted(found.items())
    }


def cache_folders(package_dir: Path) -> list[Path]:
    """Where numba caches a package's kernels: the ``__pycache__`` folders beside its sources or, with
    ``NUMBA_CACHE_DIR`` set, the folders numba names after the package there (``sim_core_<hash of its path>``)."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return sorted(p for p in Path(user).glob(f"{package_dir.name}_*") if p.is_dir())
    return sorted(p for p in package_dir.rglob("__pycache__") if p.is_dir())


def record(path: Path = RECORD) -> int:
    """Write the signatures in this checkout's numba cache (``sim_core``, ``telemetry``) to ``path``; how many."""
    root = Path(__file__).resolve().parents[2]
    return write(read_cache({p: cache_folders(root / p) for p in PACKAGES}), path)


def write(signatures: dict[str, dict[str, list[list[Any]]]], path: Path = RECORD) -> int:
    """Write ``signatures`` (as :func:`read_cache` returns them) to ``path``, one signature a line; how many."""
    lines = ["{"]
    for i, (module, functions) in enumerate(signatures.items()):
        lines.append(f"{json.dumps(module)}: {{")
        for j, (function, sigs) in enumerate(functions.items()):
            lines.append(f" {json.dumps(function)}: [")
            lines += [f"  {json.dumps(sig, sort_keys=True)}," for sig in sigs]
            lines[-1] = lines[-1].rstrip(",")
            lines.append(" ]" + ("," if j < len(functions) - 1 else ""))
        lines.append("}" + ("," if i < len(signatures) - 1 else ""))
    lines.append("}")
    path.write_text("\n".join(lines) + "\n")
    return sum(len(sigs) for fns in signatures.values() for sigs in fns.values())


@dataclass(frozen=True)
class CompileReport:
    """What :func:`compile_recorded` did: signatures compiled or loaded, and those skipped (gone or failing)."""

    compiled: int
    skipped: list[str]


def serialise_cache_saves() -> None:
    """Make this process's numba cache saves take an exclusive lock on the cache folder (``fcntl.flock``).

    numba's ``IndexDataCacheFile.save`` reads a function's index, takes the first data-file name it does not list
    and writes both: two processes saving signatures of one function at once can write two signatures under one
    data-file name, and one of them then loads the other's machine code. Every process of a parallel compile (the
    warm flight and :func:`compile_recorded` beside it) calls this first."""
    import fcntl

    from numba.core import caching

    original = caching.IndexDataCacheFile.save
    if getattr(original, "serialised", False):
        return

    def save(self: Any, key: Any, data: Any) -> None:
        try:
            lock = open(os.path.join(self._cache_path, SAVE_LOCK), "a")  # noqa: SIM115 (held across the save)
        except OSError:  # a read-only cache: numba's own save fails and falls back to compiling, as without us
            original(self, key, data)
            return
        with lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            original(self, key, data)

    save.serialised = True  # type: ignore[attr-defined]
    caching.IndexDataCacheFile.save = save  # type: ignore[method-assign]


def compile_recorded_beside(path: Path) -> CompileReport:
    """:func:`compile_recorded` in a process that saves under the cache lock (the target of a spawned process)."""
    serialise_cache_saves()
    return compile_recorded(path)


def compile_recorded(path: Path = RECORD) -> CompileReport:
    """Compile (or load from the cache) every signature recorded in ``path`` into numba's cache."""
    recorded = json.loads(path.read_text()) if path.is_file() else {}
    compiled, skipped = 0, []
    for module_name, functions in recorded.items():
        for function, signatures in functions.items():
            for sig in signatures:
                where = f"{module_name}.{function}"
                try:
                    dispatcher = getattr(importlib.import_module(module_name), function)
                    dispatcher.compile(tuple(decode_type(t) for t in sig))
                except Exception as exc:  # a stale record: numba compiles at call time instead
                    skipped.append(f"{where}: {type(exc).__name__}: {exc}".splitlines()[0][:200])
                    continue
                compiled += 1
    return CompileReport(compiled, skipped)


def beyond(
    signatures: dict[str, dict[str, list[list[Any]]]], known: dict[str, dict[str, list[list[Any]]]]
) -> dict[str, dict[str, list[list[Any]]]]:
    """The signatures of ``signatures`` that ``known`` does not hold (empty functions and modules left out)."""
    out: dict[str, dict[str, list[list[Any]]]] = {}
    for module, functions in signatures.items():
        for function, sigs in functions.items():
            new = [sig for sig in sigs if sig not in known.get(module, {}).get(function, [])]
            if new:
                out.setdefault(module, {})[function] = new
    return out


def _user_cache(root: Path) -> dict[str, list[Path]]:
    return {p: sorted(d for d in root.glob(f"{p}_*") if d.is_dir()) for p in PACKAGES}


def main(argv: list[str] | None = None) -> int:
    """Record the signatures in numba caches: this checkout's, or the ``NUMBA_CACHE_DIR`` folders named, minus
    those in the ``--beyond`` folder (a cache ``acs-twin warm`` alone filled: its flight compiles those itself)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m backend.jobs.kernel_signatures", description=main.__doc__)
    parser.add_argument("caches", nargs="*", type=Path, help="NUMBA_CACHE_DIR folders a suite run filled")
    parser.add_argument("--beyond", type=Path, help="NUMBA_CACHE_DIR folder that `acs-twin warm` alone filled")
    args = parser.parse_args(argv)
    if not args.caches:
        print(f"kernel_signatures: {record()} signatures recorded in {RECORD}")
        return 0
    found: dict[str, list[Path]] = {p: [] for p in PACKAGES}
    for root in args.caches:
        for package, dirs in _user_cache(root).items():
            found[package] += dirs
    signatures = read_cache(found)
    if args.beyond:
        signatures = beyond(signatures, read_cache(_user_cache(args.beyond)))
    print(f"kernel_signatures: {write(signatures)} signatures recorded in {RECORD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
