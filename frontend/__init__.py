"""Operator-facing views: viser 3D twin scenes and the static dashboard (imports sim_core only)."""
