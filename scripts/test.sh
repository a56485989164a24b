#!/usr/bin/env bash
# Install navdeck with its test extras into .venv, install the system packages the tests need when
# running as root (Debian's chromium for the browser tests, Debian's postgresql for the PostgreSQL
# variants of the storage, API and migration tests: tests/pg.py starts a throw-away server from its
# binaries), lint, and run the whole test suite.
set -euo pipefail
NAVDECK_EXTRAS=dev
source "$(dirname "$0")/_venv.sh"

need_apt=()
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
# Debian keeps initdb/pg_ctl in /usr/lib/postgresql/<major>/bin, off PATH.
compgen -G "/usr/lib/postgresql/*/bin/initdb" >/dev/null || command -v initdb >/dev/null 2>&1 \
  || need_apt+=(postgresql)
# The firmware tests compile robot/firmware/ for the host (cc) and cross-compile it for the STM32F429.
command -v cc >/dev/null 2>&1 || need_apt+=(gcc)
command -v arm-none-eabi-gcc >/dev/null 2>&1 || need_apt+=(gcc-arm-none-eabi libnewlib-arm-none-eabi)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing ${need_apt[*]} from Debian packages" >&2
    if [[ " ${need_apt[*]} " == *" postgresql "* ]]; then  # tests make their own cluster: no system one
      mkdir -p /etc/postgresql-common
      grep -qs '^create_main_cluster' /etc/postgresql-common/createcluster.conf \
        || echo "create_main_cluster = false" >>/etc/postgresql-common/createcluster.conf
    fi
    apt-get update -qq >&2 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >&2
  else
    echo "note: ${need_apt[*]} missing and not root: browser / PostgreSQL / firmware tests will be skipped" >&2
  fi
fi

.venv/bin/ruff check .
# Two workers (the CI machine has 2 cores); tests of one file stay on one worker (shared fixtures).
exec .venv/bin/pytest -n "${NAVDECK_TEST_WORKERS:-2}" --dist loadfile "$@"
