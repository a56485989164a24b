"""``navdeck`` command line: one sub-command per module in ``app/commands/``.

Each module there defines ``register(subparsers)`` which adds its parser and sets ``func``.
A command reports a user error by raising ``CliError``: the CLI prints one line and exits 2.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import app.commands as commands_pkg


class CliError(Exception):
    """A user-facing error: printed as one line, no traceback."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="navdeck", description="Operator station and navigation server for small lidar robots."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands_pkg.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands_pkg.__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"navdeck {args.command}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    # Re-import so commands and this entry point share one ``CliError`` class.
    from app.cli import main as _main

    sys.exit(_main())
