#!/usr/bin/env bash
# Install navdeck into .venv (first run only) and start the dashboard on the embedded default:
# a simulated robot in a stock world, SQLite in var/navdeck.db. Extra arguments go to `navdeck serve`.
set -euo pipefail
source "$(dirname "$0")/_venv.sh"
exec .venv/bin/navdeck serve "$@"
