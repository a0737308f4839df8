"""Telemetry dictionaries the server knows: the shipped ones plus those uploaded by operators.

An uploaded definition is stored as ``data_dir/dictionaries/<name>`` with ``<name>.meta.json``
holding the APID and time code a ccsdspy CSV needs (XTCE and YAML carry their own).
"""

from __future__ import annotations

import json
import re
import threading
from pathlib import Path
from typing import Any

__all__ = ["DictionaryCatalogue", "DICTIONARY_SUFFIXES"]

DICTIONARY_SUFFIXES = (".yaml", ".yml", ".xml", ".csv")
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,120}$")


def _check_name(name: str) -> str:
    if not _SAFE_NAME.match(name) or Path(name).suffix.lower() not in DICTIONARY_SUFFIXES:
        raise ValueError(f"dictionary: {name!r} must be a plain file name ending in {DICTIONARY_SUFFIXES}")
    return name


class DictionaryCatalogue:
    """Loads dictionaries by file name (uploaded ones first, else shipped), cached in memory."""

    def __init__(self, folder: Path) -> None:
        self._folder = folder
        self._cache: dict[str, Any] = {}
        self._lock = threading.Lock()

    def names(self) -> list[str]:
        """File names of the shipped and uploaded dictionaries."""
        from telemetry.dictionary import SHIPPED

        found = {p.name for p in SHIPPED.iterdir() if p.suffix in DICTIONARY_SUFFIXES}
        if self._folder.is_dir():
            found |= {p.name for p in self._folder.iterdir()
                      if p.suffix in DICTIONARY_SUFFIXES and not p.name.startswith(".")}
        return sorted(found)

    def load(self, name: str) -> Any:
        """The telemetry.dictionary.Dictionary called ``name`` (ValueError naming ``dictionary``)."""
        from telemetry.dictionary import load_dictionary

        _check_name(name)
        with self._lock:
            if name in self._cache:
                return self._cache[name]
        uploaded = self._folder / name
        if uploaded.is_file():
            meta = json.loads((self._folder / f"{name}.meta.json").read_text())
            dictionary = load_dictionary(uploaded, apid=meta["apid"], time_code=meta["time_code"])
        else:
            dictionary = load_dictionary(name)
        with self._lock:
            self._cache[name] = dictionary
        return dictionary

    def add(self, name: str, content: bytes, apid: int | None, time_code: str | None) -> Any:
        """Store an uploaded definition (YAML, XTCE or ccsdspy CSV + APID) once it loads cleanly."""
        from telemetry.dictionary import load_dictionary

        _check_name(name)
        self._folder.mkdir(parents=True, exist_ok=True)
        path, backup = self._folder / name, self._folder / f".previous.{name}"
        if path.exists():
            path.replace(backup)  # the file is loaded under its own name (a CSV's stem names its packet)
        path.write_bytes(content)
        try:
            dictionary = load_dictionary(path, apid=apid, time_code=time_code)
        except Exception:
            path.unlink()
            if backup.exists():
                backup.replace(path)
            raise
        backup.unlink(missing_ok=True)
        (self._folder / f"{name}.meta.json").write_text(json.dumps({"apid": apid, "time_code": time_code}))
        with self._lock:
            self._cache[name] = dictionary
        return dictionary
