"""DESIGN.md layers: sim_core imports nothing of ours; telemetry and frontend only sim_core; nothing imports backend."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = {"sim_core", "telemetry", "frontend", "backend"}
ALLOWED = {
    "sim_core": {"sim_core"},
    "telemetry": {"sim_core", "telemetry"},
    "frontend": {"sim_core", "frontend"},
    "backend": OURS,
}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module.split(".")[0])
    return found & OURS


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_its_allowed_layers(package):
    offenders = {
        str(path.relative_to(ROOT)): sorted(_imports(path) - ALLOWED[package])
        for path in (ROOT / package).rglob("*.py")
        if _imports(path) - ALLOWED[package]
    }
    assert not offenders, f"layer violations: {offenders}"


def test_nothing_outside_backend_imports_backend():
    users = [
        str(p.relative_to(ROOT))
        for pkg in ("sim_core", "telemetry", "frontend")
        for p in (ROOT / pkg).rglob("*.py")
        if "backend" in _imports(p)
    ]
    assert not users
