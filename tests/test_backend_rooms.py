"""The backend's rooms stay livable: no import circle between its modules, a small top level."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BACKEND = ROOT / "backend"
MAX_TOP_LEVEL_MODULES = 10


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(path): path for path in BACKEND.rglob("*.py")}


def _imported(path: Path, modules: dict[str, Path]) -> set[str]:
    """Backend modules ``path`` imports, at module level or inside functions (a lazy import is still a circle)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return {name for name in found if name in modules and modules[name].name != "__init__.py"}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` as a list of modules, or None (depth-first search)."""
    done: set[str] = set()
    for start in sorted(graph):
        stack: list[tuple[str, list[str]]] = [(start, sorted(graph[start]))]
        path = [start]
        while stack:
            node, todo = stack[-1]
            if not todo:
                stack.pop()
                path.pop()
                done.add(node)
                continue
            nxt = todo.pop()
            if nxt in path:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in done:
                stack.append((nxt, sorted(graph[nxt])))
                path.append(nxt)
    return None


def test_no_import_circle_inside_backend():
    modules = _modules()
    graph = {name: _imported(path, modules) - {name} for name, path in modules.items()}
    circle = _cycle(graph)
    assert circle is None, f"import circle: {' -> '.join(circle or [])}"


def test_backend_top_level_stays_small():
    top = sorted(path.name for path in BACKEND.glob("*.py"))
    assert len(top) <= MAX_TOP_LEVEL_MODULES, f"{len(top)} modules at backend/ top level: {top}"


def test_every_room_is_a_package():
    rooms = [d for d in BACKEND.iterdir() if d.is_dir() and any(d.glob("*.py"))]
    assert all((room / "__init__.py").exists() for room in rooms), rooms


def test_the_server_starts_without_loading_the_flight_engine_or_dask():
    """Importing the app loads neither sim_core.engine (its numba kernels were ~60 % of the import) nor
    distributed: a simulation, a diagnosis or a live twin loads the engine when it first flies, the cluster's
    first use loads Dask."""
    probe = "import sys, backend.app; print(sorted({'sim_core.engine', 'distributed'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stderr
