"""Repositories: the only code that touches a database session for the backend's tables."""
