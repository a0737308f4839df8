"""Ingest: the gateway to ``telemetry``, the live link process and its relay, the sample cache, dictionaries."""
