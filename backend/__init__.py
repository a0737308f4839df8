"""The acs-twin server: FastAPI application, auth, jobs, twin sessions and the command line.

Imports sim_core, telemetry and frontend; nothing imports backend (DESIGN.md)."""
