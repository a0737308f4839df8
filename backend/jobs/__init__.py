"""Simulation jobs: the job manager and its repository, the simulators, the trajectory files."""
