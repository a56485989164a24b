#!/usr/bin/env bash
# Install navdeck with its test extras into .venv, install the system packages the browser tests
# need (Debian's chromium, when running as root), lint, and run the whole test suite.
set -euo pipefail
NAVDECK_EXTRAS=dev
source "$(dirname "$0")/_venv.sh"

need_apt=()
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing ${need_apt[*]} from Debian packages" >&2
    apt-get update -qq >&2 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >&2
  else
    echo "note: ${need_apt[*]} missing and not root: browser tests will be skipped" >&2
  fi
fi

.venv/bin/ruff check .
exec .venv/bin/pytest "$@"
