"""Subcommands of the ``mgelens`` CLI: one module each, exposing ``register(subparsers)``."""
