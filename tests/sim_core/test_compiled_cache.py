"""The numba cache never serves a caller compiled against an old callee (sim_core.compiled_cache)."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import sim_core
from sim_core import compiled_cache

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef value():\n    return {}\n"
CALLER = "from numba import njit\n\nfrom pkg.callee import value\n\n\n@njit(cache=True)\ndef twice():\n    return 2 * value()\n"


def _run(root: Path, guarded: bool, cache_dir: Path | None = None) -> int:
    """A fresh interpreter importing ``pkg`` (guarded like sim_core or not) and calling the cached caller; numba's
    cache beside the sources, or under ``cache_dir`` (NUMBA_CACHE_DIR) when given."""
    code = textwrap.dedent(f"""
        import sys
        from pathlib import Path
        sys.path.insert(0, {str(root)!r})
        if {guarded}:
            from sim_core.compiled_cache import guard
            guard(Path({str(root / "pkg")!r}))
        from pkg.caller import twice
        print(twice())
    """)
    env = {"PYTHONPATH": str(Path(sim_core.__file__).parent.parent), "PATH": "/usr/bin:/bin"}
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    out = subprocess.run(  # -B: a module rewritten within the same second at the same size (callee.py's 1 → 5)
        [sys.executable, "-B", "-c", code],  # would otherwise be imported from its stale .pyc (mtime has 1 s steps)
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    return int(out.stdout.strip())


def _package(root: Path, value: int) -> None:
    pkg = root / "pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "callee.py").write_text(CALLEE.format(value))


def test_numba_alone_serves_a_stale_callee_and_the_guard_recompiles(tmp_path):
    plain, guarded = tmp_path / "plain", tmp_path / "guarded"
    for root in (plain, guarded):
        root.mkdir()
        _package(root, 1)
        assert _run(root, root is guarded) == 2
        _package(root, 5)  # the callee changes, the caller's file does not
    assert _run(plain, False) == 2  # numba's own cache: the caller still has value() == 1 inlined
    assert _run(guarded, True) == 10  # guarded: recompiled against the new callee


def test_the_guard_clears_a_user_cache_dir_too(tmp_path):
    """With NUMBA_CACHE_DIR numba keeps a folder's cache in ``<folder>_<sha1 of its path>`` under it (the guard
    looked for a folder named like the package there, found none and cleared nothing)."""
    cache = tmp_path / "numba-cache"
    _package(tmp_path, 1)
    assert _run(tmp_path, True, cache) == 2
    assert not list((tmp_path / "pkg").glob("__pycache__/*.nbi"))  # numba used the user cache dir
    _package(tmp_path, 5)
    assert _run(tmp_path, True, cache) == 10


def test_the_stamp_follows_the_sources(tmp_path):
    _package(tmp_path, 1)
    pkg = tmp_path / "pkg"
    assert compiled_cache.guard(pkg) and not compiled_cache.guard(pkg)  # first call stamps, second finds it current
    (pkg / "callee.py").write_text(CALLEE.format(3))
    assert compiled_cache.guard(pkg) == ["callee", "caller"]  # the callee changed, the caller imports it


def test_unchanged_sources_are_recognised_by_their_digest_without_parsing(tmp_path, monkeypatch):
    """Every process importing sim_core runs the guard: with nothing changed it must not parse the modules."""
    _package(tmp_path, 1)
    pkg = tmp_path / "pkg"
    assert compiled_cache.guard(pkg) == ["__init__", "callee", "caller"]

    def no_parse(*_):
        raise AssertionError("parsed the modules although no source changed")

    monkeypatch.setattr(compiled_cache, "_imported_modules", no_parse)
    assert compiled_cache.guard(pkg) == []
    monkeypatch.undo()
    (pkg / "callee.py").write_text(CALLEE.format(3))
    assert compiled_cache.guard(pkg) == ["callee", "caller"]


def test_a_stamp_without_the_digest_is_completed_and_clears_nothing(tmp_path):
    _package(tmp_path, 1)
    pkg = tmp_path / "pkg"
    stamp = compiled_cache.stamp_path(pkg)
    stamp.parent.mkdir(parents=True)
    stamp.write_text(json.dumps(compiled_cache.module_hashes(pkg)))  # as written before the digest existed
    assert compiled_cache.guard(pkg) == []
    assert compiled_cache.SOURCES_KEY in json.loads(stamp.read_text())


def test_a_change_clears_only_the_modules_that_see_it(tmp_path):
    _package(tmp_path, 1)
    pkg = tmp_path / "pkg"
    (pkg / "other.py").write_text("from numba import njit\n\n\n@njit(cache=True)\ndef three():\n    return 3\n")
    assert _run(tmp_path, True) == 2
    compiled = {f.name for f in (pkg / "__pycache__").iterdir() if f.suffix in compiled_cache.CACHE_SUFFIXES}
    assert any(n.startswith("caller.") for n in compiled) and any(n.startswith("callee.") for n in compiled)
    (pkg / "other.py").write_text("from numba import njit\n\n\n@njit(cache=True)\ndef three():\n    return 4\n")
    assert compiled_cache.guard(pkg) == ["other"]
    kept = {f.name for f in (pkg / "__pycache__").iterdir() if f.suffix in compiled_cache.CACHE_SUFFIXES}
    assert kept == compiled  # other.py was never compiled; caller and callee keep their machine code
    (pkg / "callee.py").write_text(CALLEE.format(5))
    assert compiled_cache.guard(pkg) == ["callee", "caller"]
    assert not any(f.suffix in compiled_cache.CACHE_SUFFIXES for f in (pkg / "__pycache__").iterdir())
    assert _run(tmp_path, True) == 10


def test_imports_are_found_in_every_spelling():
    modules = {"a", "b", "c", "d", "e"}
    source = (
        "import pkg.a\nfrom pkg import b as bb\nfrom pkg.c import f\nfrom . import d\ndef g():\n    from .e import h\n"
    )
    assert compiled_cache._imported_modules(source, "pkg", modules) == modules
    assert compiled_cache._imported_modules("import numpy\nfrom pkgx import a\n", "pkg", modules) == set()
