"""``navdeck serve``: start the server with a simulated or a real robot."""

from __future__ import annotations

import argparse
import logging
import sys

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("serve", help="start the dashboard and navigation server")
    p.add_argument("--robot", default="sim", help="'sim' or serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1")
    p.add_argument("--profile", default="skid4", help="stock profile name or path to a profile TOML")
    p.add_argument("--world", default="apartment", help="stock world name or map YAML (simulator only)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--db", default="", help="database URL (default: NAVDECK_DATABASE_URL or var/navdeck.db)")
    p.add_argument("--seed", type=int, default=0, help="simulator random seed")
    p.add_argument("--no-viewer", action="store_true", help="do not start the 3D view")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from app.drivers import DriverConfigError
    from app.main import UVICORN_OPTIONS, create_app
    from app.runtime import Runtime
    from app.settings import Settings
    from robot.profiles import ProfileError

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger("alembic").setLevel(logging.WARNING)
    settings = Settings(
        robot=args.robot,
        profile=args.profile,
        world=args.world,
        host=args.host,
        port=args.port,
        db_url=args.db,
        seed=args.seed,
        viewer=not args.no_viewer,
    )
    try:
        runtime = Runtime.build(settings)
    except (ProfileError, DriverConfigError) as exc:
        raise CliError(str(exc)) from None
    except Exception as exc:  # database URL problems and the like: one line, not a traceback
        raise CliError(f"cannot start: {type(exc).__name__}: {exc}") from None
    if not settings.is_local:
        print(
            f"note: listening on {settings.host}: sign-in is required (add users with "
            "'navdeck user add NAME --role operator'); put TLS in front (docs/deployment.md).",
            file=sys.stderr,
        )
    host = "127.0.0.1" if settings.host in ("0.0.0.0", "::") else settings.host
    world = f", world {runtime.world_name}" if runtime.world_name else ""  # a real robot has none
    print(
        f"navdeck: dashboard at http://{host}:{settings.port}/  (robot {settings.robot}, profile "
        f"{runtime.profile.name}{world}, database {settings.db_url})",
        flush=True,
    )
    app = create_app(runtime)
    uvicorn.run(app, host=settings.host, port=settings.port, **UVICORN_OPTIONS)
    return 0
