"""Exported surface of the packet modules: every name in ``__all__`` exists, is documented, and typed."""

from __future__ import annotations

import importlib
import inspect

import pytest

MODULES = [
    "telemetry.ccsds",
    "telemetry.dictionary",
    "telemetry.decoding",
    "telemetry.validation",
    "telemetry.ingest_report",
    "telemetry.ground_files",
    "telemetry.encoding",
]


@pytest.mark.parametrize("module_name", MODULES)
def test_exported_members_are_documented_and_typed(module_name: str) -> None:
    module = importlib.import_module(module_name)
    assert module.__doc__
    for name in module.__all__:
        member = getattr(module, name)
        if inspect.isfunction(member):
            assert member.__doc__, f"{module_name}.{name} has no docstring"
            hints = inspect.signature(member)
            assert hints.return_annotation is not inspect.Signature.empty, f"{module_name}.{name} return type"
            for p in hints.parameters.values():
                assert p.annotation is not inspect.Parameter.empty, f"{module_name}.{name}({p.name}) type"
        elif inspect.isclass(member):
            assert member.__doc__, f"{module_name}.{name} has no docstring"
