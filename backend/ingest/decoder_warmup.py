"""Imported by the upload decoders' fork server (backend.ingest.upload_decoder.PRELOAD), never by the server:
decodes one packet of each type of the shipped reference dictionary, so the numba decode kernels are loaded once
in the fork server and every decoder it forks starts with them (a fresh process loads them on its first chunk:
1-3 s on a loaded 2-core machine, at the decoder's NICENESS)."""

from __future__ import annotations

import contextlib

from telemetry.dictionary import load_dictionary
from telemetry.live import warm_decoder

__all__: list[str] = []

REFERENCE_DICTIONARY = "reference_satellite.yaml"  # telemetry.emulator's (not imported: it imports sim_core)

with contextlib.suppress(Exception):  # only a head start: a decoder loads what it lacks on its first chunk
    warm_decoder(load_dictionary(REFERENCE_DICTIONARY))
