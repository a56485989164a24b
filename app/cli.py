"""``navdeck`` command line: one sub-command per module in ``app/commands/``.

Each module there defines ``register(subparsers)`` which adds its parser and sets ``func``.
A command reports a user error by raising ``CliError``: the CLI prints one line and exits 2.
Every command module is imported to build the parser, so a command imports its heavy modules inside
its ``run`` function: ``navdeck --help`` loads neither the server nor the navigation stack.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
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


_NEGATIVE_LIST = re.compile(r"^-\.?\d[^,]*,")
"""A value such as ``-1.5,2,0``: argparse only takes ``-1.5`` alone as a negative number; with the
comma it reads the token as an unknown option ("expected one argument")."""


def attach_negative_values(argv: list[str]) -> list[str]:
    """``--start -1.5,2,0`` -> ``--start=-1.5,2,0``, the spelling argparse accepts, so users can
    type coordinates the natural way. Only comma lists starting with a negative number are joined:
    no option of navdeck looks like that, and plain negative numbers already parse."""
    out: list[str] = []
    for tok in argv:
        prev = out[-1] if out else ""
        if (
            _NEGATIVE_LIST.match(tok)
            and prev.startswith("--")
            and "=" not in prev
            and prev != "--"
            and "--" not in out[:-1]
        ):
            out[-1] = f"{prev}={tok}"
        else:
            out.append(tok)
    return out


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse a navdeck command line (``sys.argv[1:]`` by default)."""
    return build_parser().parse_args(attach_negative_values(sys.argv[1:] if argv is None else list(argv)))


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
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
