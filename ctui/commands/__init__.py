"""Subcommands. Each module: ``register(subparsers)`` sets ``func=run``; ``run(args) -> int``.

Keep top-level imports to argparse/stdlib: heavy imports go inside ``run``.
"""
