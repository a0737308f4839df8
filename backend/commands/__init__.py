"""Subcommands of ``acs-twin``: each module defines ``register(subparsers)`` and is found by name."""
