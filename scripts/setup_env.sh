#!/usr/bin/env bash
# Create or refresh the project's virtual environment in <repo>/.venv:
#   system python3 -m venv, latest pip, then an editable install `pip install -e .[wheels,test]`
#   (rclpy + messages as PyPI wheels, numpy/scipy/mcap/matplotlib, pytest, rosbags, colcon).
# Idempotent: once a stamp newer than setup.py/setup.cfg/package.xml/this script exists and the venv
# still imports the package, a re-run takes well under a second. Quiet; on failure prints pip's log.
#
# Usage: bash scripts/setup_env.sh          (other scripts source it; it prints the venv path on success)
# Env:   PYTHON=python3.x   interpreter to build the venv from (default: python3 on PATH)
#        BLDC_VENV=path     venv location (default: <repo>/.venv)
#        BLDC_SETUP_FORCE=1 reinstall even when the stamp is fresh
#
# Presets and the editable install: `pip install -e` skips data_files, so <venv>/share/bldc_actuator/config
# does NOT exist here. The code finds presets relative to the package itself: <pkg>/../config (source tree,
# editable install) first, then <prefix>/share/bldc_actuator/config where <prefix> is four levels above the
# package directory (<prefix>/lib/pythonX.Y/site-packages/bldc_actuator: `pip install .` into a venv and
# colcon's install/bldc_actuator both lay it out this way). ament_index is not needed for that (it fails in a
# pip venv unless AMENT_PREFIX_PATH is set).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)"
VENV="${BLDC_VENV:-$REPO/.venv}"
PY="${PYTHON:-python3}"
STAMP="$VENV/.bldc_setup_stamp"
LOG="$VENV/setup.log"

# A parent process started from another ROS-wheels venv leaks its bootstrap state; the venv's own
# interpreter must bootstrap itself (it re-executes with its own LD_LIBRARY_PATH).
if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" ]]; then
    unset _ROS_WHEELS_BOOTSTRAP_COMPLETE LD_LIBRARY_PATH
fi
# pip must not install into a different venv that happens to be active.
unset PYTHONHOME PIP_USER || true

fresh() {
    [[ -f "$STAMP" && "${BLDC_SETUP_FORCE:-0}" != 1 ]] || return 1
    local f
    for f in setup.py setup.cfg package.xml scripts/setup_env.sh; do
        [[ "$STAMP" -nt "$REPO/$f" ]] || return 1
    done
    # the venv still works and the editable install still points at this checkout
    [[ "$("$VENV/bin/python" -c 'import bldc_actuator, os; print(os.path.dirname(os.path.realpath(bldc_actuator.__file__)))' 2>/dev/null)" \
        == "$REPO/bldc_actuator" ]]
}

if fresh; then
    echo "$VENV"
    exit 0
fi

# One setup at a time per checkout (e.g. demo.sh and test.sh started together): lock this script file,
# then look again, since the other run may just have finished.
if command -v flock >/dev/null 2>&1; then
    exec 9<"${BASH_SOURCE[0]}"
    flock 9
    if fresh; then
        echo "$VENV"
        exit 0
    fi
fi

run() {  # run quietly, show the log on failure
    if ! "$@" >>"$LOG" 2>&1; then
        echo "setup_env.sh: FAILED: $*" >&2
        tail -n 60 "$LOG" >&2
        echo "setup_env.sh: full log: $LOG" >&2
        exit 1
    fi
}

if [[ ! -x "$VENV/bin/python" ]] || ! "$VENV/bin/python" -c 'import sys' >/dev/null 2>&1; then
    echo "setup_env.sh: creating $VENV with $("$PY" --version 2>&1) ..." >&2
    rm -rf "$VENV"
    "$PY" -m venv "$VENV"
fi
: >"$LOG"
echo "setup_env.sh: installing bldc_actuator[wheels,test] into $VENV (about a minute the first time) ..." >&2
start=$SECONDS
run "$VENV/bin/python" -m pip install --upgrade pip
run "$VENV/bin/python" -m pip install -e "$REPO[wheels,test]"
# smoke test: the package, rclpy (through the wheels' bootstrapper) and colcon are usable
run "$VENV/bin/python" -c 'import bldc_actuator, rclpy, numpy, scipy, yaml, mcap, pytest'
# compile the physics kernel into numba's on-disk cache now (8 s of CPU): a first node start, test or demo
# would otherwise compile it (a minute and more on a busy machine, during which the node's loop cannot run)
run "$VENV/bin/python" -c 'from bldc_actuator.model import warm_up; warm_up()'
touch "$STAMP"
echo "setup_env.sh: done in $((SECONDS - start)) s" >&2
echo "$VENV"
