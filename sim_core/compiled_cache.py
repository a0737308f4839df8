"""Guard of numba's on-disk cache against stale callees, one module at a time.

numba's ``cache=True`` keys a compiled function on its own source file's time stamp only: when a function
it calls (in another module) changes, the caller's cached machine code still holds the old callee.
:func:`guard` stamps the cache, per module, with a hash of the module's source and of every module of the
package it imports, directly or not; a module whose hash changed since its cache was written loses its
cached index/data files (numba names them after the module's file) before anything is compiled or loaded,
so it recompiles against the current callees, while modules that neither changed nor import a changed one
keep their machine code. The only file I/O of ``sim_core``; it runs once, from ``sim_core/__init__.py``.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
from pathlib import Path

__all__ = ["cache_dirs", "guard", "module_hashes", "sources_digest", "stamp_path"]

STAMP_NAME = "numba-source.json"
SOURCES_KEY = "__sources__"  # the stamp's digest of all sources (a key no module of the package is named)
CACHE_SUFFIXES = (".nbi", ".nbc")


def _imported_modules(source: str, package: str, modules: set[str]) -> set[str]:
    """Modules of ``package`` (names in ``modules``) that ``source`` imports anywhere in its body."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package if node.level else (node.module or "")
            if node.level and node.module:
                base = f"{package}.{node.module}"
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        for name in names:
            head, _, rest = name.partition(".")
            if head == package and rest.split(".")[0] in modules:
                found.add(rest.split(".")[0])
    return found


def sources_digest(package_dir: Path) -> str:
    """SHA-256 over every top-level module's name and source: equal to the stamp's, no module changed (read in
    about a millisecond, where :func:`module_hashes` parses every module to follow its imports)."""
    digest = hashlib.sha256()
    for path in sorted(package_dir.glob("*.py")):
        digest.update(path.stem.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def module_hashes(package_dir: Path) -> dict[str, str]:
    """Per top-level module of the package: SHA-256 over its source and those of the package modules it
    imports, transitively (sorted by name)."""
    sources = {p.stem: p.read_bytes() for p in sorted(package_dir.glob("*.py"))}
    imports = {m: _imported_modules(s.decode(), package_dir.name, set(sources)) for m, s in sources.items()}
    hashes = {}
    for module in sources:
        closure, frontier = {module}, [module]
        while frontier:
            for dep in imports[frontier.pop()] - closure:
                closure.add(dep)
                frontier.append(dep)
        digest = hashlib.sha256()
        for dep in sorted(closure):
            digest.update(dep.encode() + b"\0" + sources[dep])
        hashes[module] = digest.hexdigest()
    return hashes


def cache_dirs(package_dir: Path) -> list[Path]:
    """Where numba caches the package's functions: the ``__pycache__`` folders beside the sources, or, when
    ``NUMBA_CACHE_DIR`` is set, the folder numba names for each source folder under it (``<folder>_<sha1 of its
    path>``, numba's own ``_CacheLocator.get_suitable_cache_subpath``)."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        from numba.core.caching import _CacheLocator

        names = {_CacheLocator.get_suitable_cache_subpath(str(f)) for f in package_dir.rglob("*.py")}  # type: ignore[no-untyped-call]
        return sorted(p for p in (Path(user) / name for name in names) if p.is_dir())
    return sorted(p for p in package_dir.rglob("__pycache__") if p.is_dir())


def stamp_path(package_dir: Path) -> Path:
    """File holding, per module, the source hash its cache was written for (JSON)."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    root = Path(user) if user else package_dir / "__pycache__"
    return root / f"{package_dir.name}-{STAMP_NAME}"


def _read_stamp(stamp: Path) -> dict[str, str]:
    try:
        value = json.loads(stamp.read_text())
    except (OSError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}


def guard(package_dir: Path) -> list[str]:
    """Delete the numba cache files of every module whose hash changed since they were written; the modules
    cleared, sorted (empty when the whole cache is current).

    Every process importing the package runs this: when the sources' digest equals the stamp's (nothing changed
    since it was written) it returns at once, without parsing the modules.
    File-system errors (a read-only install) leave the cache as it is: numba then falls back to compiling.
    """
    stamp = stamp_path(package_dir)
    written = _read_stamp(stamp)
    digest = sources_digest(package_dir)
    if written.get(SOURCES_KEY) == digest:
        return []
    current = module_hashes(package_dir)
    stale = sorted(m for m, h in current.items() if written.get(m) != h)
    prefixes = tuple(f"{m}." for m in stale)
    try:
        for d in cache_dirs(package_dir) if stale else []:
            for f in d.iterdir():
                if f.suffix in CACHE_SUFFIXES and f.name.startswith(prefixes):
                    f.unlink(missing_ok=True)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({**current, SOURCES_KEY: digest}, indent=0, sort_keys=True) + "\n")
        tmp.replace(stamp)
    except OSError:
        return []
    return stale
