"""Telemetry dictionaries the server knows: the shipped ones (read-only) plus those uploaded by operators.

An uploaded definition is stored as ``data_dir/dictionaries/<name>`` with ``<name>.meta.json``
holding the APID and time code a ccsdspy CSV needs (XTCE and YAML carry their own) and its version.
Every upload is a new version: the one it replaces is kept as ``.versions/<name>.v<N>`` (with its
meta), files reach their final name only by an atomic rename after an fsync, and a file that cannot
be read (a crash mid-write on an older build, a disk error) is a 422 naming the dictionary.
"""

from __future__ import annotations

import json
import os
import re
import threading
from pathlib import Path
from typing import Any

from backend.core.errors import ApiError, described_pattern
from telemetry.dictionary import Dictionary, Limits

__all__ = ["DICTIONARY_NAME", "DICTIONARY_NAME_MAX", "DICTIONARY_SUFFIXES", "DictionaryCatalogue"]

DICTIONARY_SUFFIXES = (".yaml", ".yml", ".xml", ".csv")
# A dictionary's name is its file name: a letter or digit, then letters, digits, '_', '.', '-', ending in one of
# DICTIONARY_SUFFIXES in any case. The API declares it (OpenAPI pattern and maxLength), so a bad name is a 422
# before an upload's body is read, and generated requests (tests/backend/test_openapi_fuzz.py) name real files.
DICTIONARY_NAME_MAX = 121
DICTIONARY_NAME = described_pattern(
    r"^[A-Za-z0-9][A-Za-z0-9_.-]*\.(?:"
    + "|".join("".join(f"[{c.upper()}{c}]" for c in suffix[1:]) for suffix in DICTIONARY_SUFFIXES)
    + ")$",
    "a plain file name (a letter or digit, then letters, digits, '_', '.', '-') ending in "
    + ", ".join(DICTIONARY_SUFFIXES),
)
_NAME = re.compile(DICTIONARY_NAME)
VERSIONS = ".versions"


def _check_name(name: str) -> str:
    if len(name) > DICTIONARY_NAME_MAX or not _NAME.fullmatch(name):
        raise ValueError(f"dictionary: {name!r} must be a plain file name ending in {DICTIONARY_SUFFIXES}")
    return name


def _body_error(exc: Exception, path: Path) -> Exception:
    """A definition that does not load as a ValueError naming the upload's body, never the server's file path
    (the loaders name the file they read: right for the CLI, the data folder's layout to an API client)."""
    if isinstance(exc, UnicodeDecodeError):
        return ValueError(f"body: not UTF-8 text: {exc}")
    if isinstance(exc, ValueError) and str(exc).startswith(f"{path}: "):
        return ValueError(f"body: {str(exc).removeprefix(f'{path}: ')}")
    return exc


def _write_atomically(path: Path, content: bytes) -> None:
    """``path`` holds either its old content or all of ``content``, never a part (fsync, then rename)."""
    part = path.with_name(f".part.{path.name}")
    with part.open("wb") as f:
        f.write(content)
        f.flush()
        os.fsync(f.fileno())
    part.replace(path)


class DictionaryCatalogue:
    """Loads dictionaries by file name (uploaded ones first, else shipped), cached in memory."""

    def __init__(self, folder: Path) -> None:
        self._folder = folder
        self._cache: dict[str, Dictionary] = {}
        self._lock = threading.Lock()

    def names(self) -> list[str]:
        """File names of the shipped and uploaded dictionaries."""
        from telemetry.dictionary import SHIPPED

        found = {p.name for p in SHIPPED.iterdir() if p.suffix in DICTIONARY_SUFFIXES}
        if self._folder.is_dir():
            found |= {
                p.name for p in self._folder.iterdir() if p.suffix in DICTIONARY_SUFFIXES and not p.name.startswith(".")
            }
        return sorted(found)

    def _meta(self, name: str) -> dict[str, Any]:
        try:
            return json.loads((self._folder / f"{name}.meta.json").read_text())
        except (OSError, ValueError):
            return {}  # meta lost or torn: a CSV then asks for its APID, YAML/XTCE need none

    def load(self, name: str) -> Dictionary:
        """The telemetry.dictionary.Dictionary called ``name`` (ValueError naming ``dictionary``)."""
        from telemetry.dictionary import load_dictionary

        _check_name(name)
        with self._lock:
            if name in self._cache:
                return self._cache[name]
        uploaded = self._folder / name
        try:
            if uploaded.is_file():
                meta = self._meta(name)
                dictionary = load_dictionary(
                    uploaded,
                    apid=meta.get("apid"),
                    time_code=meta.get("time_code"),
                    time_fields=meta.get("time_fields"),
                )
            else:
                dictionary = load_dictionary(name)
        except ValueError:
            raise
        except Exception as exc:  # a torn or corrupt file raises its parser's own errors
            raise ValueError(
                f"dictionary: {name} cannot be read ({type(exc).__name__}: {exc}); upload it again"
            ) from exc
        with self._lock:
            self._cache[name] = dictionary
        return dictionary

    def load_known(self, name: str) -> Dictionary:
        """:meth:`load` of a dictionary this catalogue lists (ValueError naming the known ones otherwise)."""
        known = self.names()
        if name not in known:
            raise ValueError(f"not a known dictionary (known: {', '.join(known)})")
        return self.load(name)

    def version(self, name: str) -> int:
        """Version of the uploaded dictionary ``name`` (0: none uploaded)."""
        return int(self._meta(name).get("version", 1)) if (self._folder / name).is_file() else 0

    def add(
        self, name: str, content: bytes, apid: int | None, time_code: str | None, time_fields: str | None = None
    ) -> tuple[Dictionary, int]:
        """Store an uploaded definition (YAML, XTCE or ccsdspy CSV + APID) once it loads; (dictionary, version).

        Shipped dictionaries are read-only (409): loosening their limits would silence real alarms.
        """
        from telemetry.dictionary import SHIPPED, load_dictionary

        _check_name(name)
        if (SHIPPED / name).exists():
            raise ApiError(
                409, f"name: {name} is a shipped dictionary and read-only; upload under another name", "name"
            )
        self._folder.mkdir(parents=True, exist_ok=True)
        with self._lock:  # one upload at a time per catalogue: versions are numbered without gaps
            path, previous = self._folder / name, self.version(name)
            kept = self._folder / VERSIONS / f"{name}.v{previous}"
            if previous:
                kept.parent.mkdir(exist_ok=True)
                path.replace(kept)  # the file is loaded under its own name (a CSV's stem names its packet)
            _write_atomically(path, content)
            try:
                dictionary = load_dictionary(path, apid=apid, time_code=time_code, time_fields=time_fields)
            except Exception as exc:
                path.unlink()
                if previous:
                    kept.replace(path)
                error = _body_error(exc, path)
                if error is exc:
                    raise
                raise error from exc
            if previous:
                (self._folder / f"{name}.meta.json").replace(kept.with_name(f"{kept.name}.meta.json"))
            meta = {"apid": apid, "time_code": time_code, "time_fields": time_fields, "version": previous + 1}
            _write_atomically(self._folder / f"{name}.meta.json", json.dumps(meta).encode())
            self._cache[name] = dictionary
        return dictionary, previous + 1

    def describe(self, archived: dict[str, int]) -> dict[str, dict[str, Any]]:
        """Units, description, enumeration and limits of archived parameters ({name: APID}).

        The archive does not record which dictionary decoded a sample, so each name takes its entry from the
        dictionary that defines the most of the satellite's (name, APID) pairs; ties go to the first by file
        name. Names no known dictionary defines are left out; an unreadable dictionary is skipped.
        """
        wanted = set(archived.items())
        best: list[tuple[int, str, dict[tuple[str, int], dict[str, Any]]]] = []
        for name in self.names():
            try:
                entries = _entries(self.load(name))
            except Exception:  # noqa: BLE001 - one broken upload must not hide the others' units
                continue
            best.append((-len(wanted & entries.keys()), name, entries))
        described: dict[str, dict[str, Any]] = {}
        for _, _, entries in sorted(best, key=lambda b: (b[0], b[1])):
            for key in wanted & entries.keys():
                described.setdefault(key[0], entries[key])
        return described


def _limits(limits: Limits) -> dict[str, float | None]:
    return {k: getattr(limits, k) for k in ("yellow_low", "yellow_high", "red_low", "red_high")}


def _entries(dictionary: Dictionary) -> dict[tuple[str, int], dict[str, Any]]:
    """(name, APID) -> JSON-ready entry of every raw and derived parameter of a dictionary."""
    entries = {}
    for apid, packet in dictionary.packets.items():
        for p in packet.parameters:
            entries[(p.name, apid)] = {
                "units": p.units,
                "description": p.description,
                "limits": _limits(p.limits),
                "enumeration": {str(k): v for k, v in p.enumeration.items()} or None,
            }
        for d in packet.derived:
            entries[(d.name, apid)] = {
                "units": d.units,
                "description": d.description,
                "limits": _limits(d.limits),
                "enumeration": None,
            }
    return entries
