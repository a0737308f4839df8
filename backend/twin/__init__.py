"""The twin: sessions aligning a simulation with telemetry, their feed, the demo twin."""
