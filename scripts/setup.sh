#!/usr/bin/env bash
# Shared set-up for scripts/run and scripts/test: a project virtualenv with smoothjog installed.
# Usage: source scripts/setup.sh run|test   ("test" also installs test tools, Chromium and CNCjs).
# The mode is required: a sourced script sees its caller's arguments when given none.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
case "${1:-}" in
  run) EXTRA="" ;;
  test) EXTRA="test" ;;
  *) echo "setup.sh: say 'run' or 'test'" >&2; return 2 2>/dev/null || exit 2 ;;
esac

pick_python() {
  for py in python3.13 python3.12 python3.11 python3; do
    if command -v "$py" >/dev/null 2>&1 &&
       "$py" -c 'import sys; raise SystemExit(sys.version_info < (3, 11))' 2>/dev/null; then
      echo "$py"; return 0
    fi
  done
  echo "smoothjog needs Python 3.11 or newer; install it (apt-get install python3) and retry." >&2
  return 1
}

if [ ! -x "$VENV/bin/python" ]; then
  PY="$(pick_python)"
  echo "setup: creating virtualenv in $VENV with $PY" >&2
  "$PY" -m venv "$VENV"
fi

# Reinstall only when pyproject.toml changed since the last install.
STAMP="$VENV/.smoothjog-installed-$EXTRA"
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ]; then
  echo "setup: installing smoothjog${EXTRA:+[$EXTRA]} into the virtualenv" >&2
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip >&2
  if [ -n "$EXTRA" ]; then
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e "$ROOT[$EXTRA]" >&2
  else
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e "$ROOT" >&2
  fi
  touch "$STAMP"
fi

if [ "$EXTRA" = "test" ] && [ ! -x /usr/bin/chromium ]; then
  echo "setup: installing Debian's Chromium for the browser tests" >&2
  SUDO=""
  if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq >&2
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >&2
fi

# A real CNCjs for the CNCjs link's tests (tests/cncjs), pinned by tools/cncjs/package-lock.json.
CNCJS_DIR="$ROOT/tools/cncjs"
CNCJS_STAMP="$CNCJS_DIR/node_modules/.smoothjog-installed"
if [ "$EXTRA" = "test" ] && { [ ! -f "$CNCJS_DIR/node_modules/cncjs/bin/cncjs" ] ||
     [ ! -f "$CNCJS_STAMP" ] || [ "$CNCJS_DIR/package-lock.json" -nt "$CNCJS_STAMP" ]; }; then
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    echo "setup: the CNCjs tests need Node.js 18+; install nodejs and npm (apt-get install nodejs npm) and retry." >&2
    return 1 2>/dev/null || exit 1
  fi
  echo "setup: installing CNCjs into tools/cncjs (npm ci) for the CNCjs link tests" >&2
  (cd "$CNCJS_DIR" && npm ci --no-audit --no-fund --prefer-offline --loglevel=error >&2)
  touch "$CNCJS_STAMP"
fi
export PATH="$VENV/bin:$PATH"
