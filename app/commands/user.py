"""``navdeck user add|list|remove|passwd``: the people who may sign in when the server is not local-only.

Passwords are read from the terminal (twice) or, for scripts, from standard input with
``--password-stdin``; they never appear on the command line (shell history, ``ps``).
"""

from __future__ import annotations

import argparse
import sys

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("user", help="manage sign-in users (operator or viewer)")
    p.add_argument("action", choices=("add", "list", "remove", "passwd"))
    p.add_argument("name", nargs="?", help="username (add, remove, passwd)")
    p.add_argument("--role", choices=("operator", "viewer"), default="viewer", help="add: the user's role")
    p.add_argument("--password-stdin", action="store_true", help="read the password from standard input")
    p.add_argument("--db", default="", help="database URL (default: NAVDECK_DATABASE_URL or var/navdeck.db)")
    p.set_defaults(func=run)


def _password(args: argparse.Namespace) -> str:
    if args.password_stdin:
        pw = sys.stdin.readline().rstrip("\r\n")
    else:
        import getpass

        pw = getpass.getpass(f"password for {args.name}: ")
        if getpass.getpass("again: ") != pw:
            raise CliError("the two passwords differ")
    return pw


def run(args: argparse.Namespace) -> int:
    from app.auth import AuthError, UserStore
    from app.db import make_engine, migrate
    from app.settings import Settings

    settings = Settings(db_url=args.db)
    if args.action != "list" and not args.name:
        raise CliError(f"user {args.action} needs a username")
    try:
        engine = make_engine(settings.db_url)
        migrate(engine)
    except Exception as exc:
        raise CliError(f"cannot open the database: {type(exc).__name__}: {exc}") from None
    store = UserStore(engine)
    try:
        if args.action == "add":
            user = store.add_user(args.name, _password(args), args.role)
            print(f"added {user.username} ({user.role})")
        elif args.action == "passwd":
            store.set_password(args.name, _password(args))
            print(f"password changed for {args.name}; its sessions were signed out")
        elif args.action == "remove":
            if not store.remove_user(args.name):
                raise CliError(f"no user {args.name!r}")
            print(f"removed {args.name}")
        else:
            for u in store.list_users():
                print(f"{u.username}\t{u.role}\t{u.created_at:%Y-%m-%d}")
    except AuthError as exc:
        raise CliError(str(exc)) from None
    finally:
        engine.dispose()
    return 0
