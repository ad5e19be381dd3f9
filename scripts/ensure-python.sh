#!/usr/bin/env bash
# Installs the Python packages the tests use (pinned) when they are missing, with pip from PyPI:
# eclipse-zenoh for the Zenoh subscriber example (consumers/python/zenoh_subscriber.py).
# In CI (CI=true) a failure is fatal: the tests that need the package must not skip there.
set -euo pipefail
PY=${PYTHON:-python3}
want=("eclipse-zenoh==1.10.2")
if "$PY" -c 'import importlib.metadata as m, sys; import zenoh; sys.exit(0 if m.version("eclipse-zenoh") == "1.10.2" else 1)' 2>/dev/null; then
    exit 0
fi
echo "installing ${want[*]} for $PY" >&2
if ! "$PY" -m pip --version >/dev/null 2>&1; then
    scripts/ensure-packages.sh python3-pip
fi
if ! "$PY" -m pip install --quiet "${want[@]}" 2>/dev/null; then
    # Debian's system Python refuses pip installs outside a venv unless told otherwise.
    "$PY" -m pip install --quiet --break-system-packages "${want[@]}" || {
        echo "error: cannot install ${want[*]} (pip install ${want[*]})" >&2
        [ "${CI:-}" = "true" ] && exit 1
        echo "warning: the Python Zenoh subscriber test will be skipped" >&2
    }
fi
