"""The kernel signatures ``acs-twin warm --recorded`` compiles: read from numba's cache indexes and compiled again
from the record, an entry whose kernel changed or went skipped (a stale record costs compile time in the tests, never
a result: ``acs-twin warm --recorded`` names each skipped entry; regenerate with ``python -m
backend.jobs.kernel_signatures`` after a suite run)."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

from backend.jobs.kernel_signatures import SAVE_LOCK, compile_recorded, decode_type, encode_type, read_cache

KERNEL = """
import numpy as np
from numba import njit


@njit(cache=True)
def twice(x):
    return 2 * x
"""


@pytest.fixture
def kernel_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A package ``kernpkg`` with one cached kernel, importable from this process."""
    package = tmp_path / "kernpkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "kern.py").write_text(KERNEL)
    monkeypatch.syspath_prepend(str(tmp_path))
    return package


def test_the_signatures_another_process_compiled_are_read_from_its_cache_index(kernel_package: Path) -> None:
    probe = "import numpy as np; from kernpkg.kern import twice; twice(np.ones(3)); twice(1.5)"
    env = {"PYTHONPATH": str(kernel_package.parent), "PATH": "/usr/bin:/bin"}
    subprocess.run([sys.executable, "-c", probe], check=True, env=env, timeout=300)
    found = read_cache({"kernpkg": [kernel_package / "__pycache__"]})
    assert found == {"kernpkg.kern": {"twice": [["float64"], ["float64[1d,C]"]]}}


def test_a_record_is_compiled_into_the_dispatcher_and_a_changed_or_gone_kernel_is_skipped(
    kernel_package: Path, tmp_path: Path
) -> None:
    record = tmp_path / "record.json"
    array = "float64[2d,C,readonly]"
    stale = ["int64", "int64"]  # the kernel since lost an argument
    record.write_text(json.dumps({"kernpkg.kern": {"twice": [[array], ["int64"], stale], "gone": [["float64"]]}}))
    report = compile_recorded(record)
    assert report.compiled == 2
    assert [s.split(":")[0] for s in report.skipped] == ["kernpkg.kern.twice", "kernpkg.kern.gone"]
    twice = importlib.import_module("kernpkg.kern").twice
    assert {tuple(encode_type(t) for t in sig) for sig in twice.signatures} == {(array,), ("int64",)}
    # saved through the lock tests/conftest.py put on numba's cache saves, and read back from the index
    assert (kernel_package / "__pycache__" / SAVE_LOCK).exists()
    assert read_cache({"kernpkg": [kernel_package / "__pycache__"]}) == {
        "kernpkg.kern": {"twice": [[array], ["int64"]]}
    }


def test_types_round_trip_through_their_json_form() -> None:
    from numba.core import types

    from sim_core.spacecraft import PlantArrays

    plant = types.NamedTuple([types.float64[:, ::1]] * 3 + [types.float64[::1]] * 6, PlantArrays)
    for t in (
        types.Array(types.float64, 2, "A", readonly=True),
        types.Array(types.boolean, 1, "C"),
        types.literal(0),
        types.literal(False),
        types.int64,
        types.UniTuple(types.float64, 3),
        types.Tuple([types.int64, types.float64]),
        plant,
    ):
        assert decode_type(json.loads(json.dumps(encode_type(t)))) == t
