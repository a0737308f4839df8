"""Telemetry of acs-twin: dictionaries, CCSDS decoding and validation, limits, passes, the archive,
live stream listeners and the spacecraft emulator (DESIGN.md layer: may import sim_core only)."""
