"""Imported first by the upload decoders' fork server (backend.ingest.upload_decoder.PRELOAD), never by the server:
lowers the fork server's CPU priority to BULK_NICENESS before anything else is imported, so that its imports, this
warm-up and every decoder it forks (they inherit it) run below the server's requests; then decodes one packet of
each type of the shipped reference dictionary, so the numba decode kernels are loaded once in the fork server and
every decoder it forks starts with them (a fresh process loads them on its first chunk: 1-3 s on a loaded 2-core
machine)."""

from __future__ import annotations

import contextlib
import os

from backend.core.processes import BULK_NICENESS

__all__: list[str] = []

REFERENCE_DICTIONARY = "reference_satellite.yaml"  # telemetry.emulator's (not imported: it imports sim_core)


def _load_decode_kernels() -> None:
    from telemetry.dictionary import load_dictionary
    from telemetry.live import warm_decoder

    warm_decoder(load_dictionary(REFERENCE_DICTIONARY))


os.nice(BULK_NICENESS)
with contextlib.suppress(Exception):  # only a head start: a decoder loads what it lacks on its first chunk
    _load_decode_kernels()
