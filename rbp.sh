#!/usr/bin/env bash
# One entry point that also does the set-up: on first use (or when pyproject.toml changes) it
# creates the virtual environment .venv with Python >= 3.11 and installs rbp into it.
#   ./rbp.sh demo      plan the bundled demo cave and write its pictures and files to out/demo
#   ./rbp.sh test      lint (ruff), type-check (mypy) and run the test suite (pytest); extra
#                      args go to pytest
#   ./rbp.sh ARGS...   any rbp command, e.g. ./rbp.sh scenario show demo-shaft -o cave.png
set -euo pipefail
CALLER_DIR="$PWD"  # rbp commands run here, so that relative paths mean what the user typed
cd "$(dirname "$0")"
VENV="${RBP_VENV:-.venv}"
case "$VENV" in /*) ;; *) VENV="$PWD/$VENV" ;; esac

find_python() {
    for py in python3.11 python3.12 python3.13 python3; do
        if command -v "$py" >/dev/null 2>&1 &&
            "$py" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
            echo "$py"
            return
        fi
    done
    echo "rbp.sh: Python 3.11 or newer is needed and was not found" >&2
    exit 1
}

setup() {
    if [ ! -x "$VENV/bin/rbp" ] || [ pyproject.toml -nt "$VENV/.rbp-installed" ]; then
        echo "rbp.sh: setting up $VENV (first run takes about a minute)" >&2
        [ -x "$VENV/bin/python" ] || "$(find_python)" -m venv "$VENV"
        # test: the test tools; import: rbp scenario import's readers, which its tests need
        "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -e ".[test,import]"
        touch "$VENV/.rbp-installed"
    fi
}

setup
export LCM_DEFAULT_URL="${LCM_DEFAULT_URL:-memq://}"  # never UDP multicast by accident
export MPLBACKEND=Agg
case "${1:-}" in
    test)
        shift
        "$VENV/bin/ruff" check .
        "$VENV/bin/mypy"  # the library, as [tool.mypy] in pyproject.toml says
        exec "$VENV/bin/python" -m pytest "$@"
        ;;
    demo)
        shift
        exec "$VENV/bin/rbp" demo "$@"
        ;;
    *)
        cd "$CALLER_DIR"
        exec "$VENV/bin/rbp" "$@"
        ;;
esac
