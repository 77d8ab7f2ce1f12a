#!/usr/bin/env bash
# Run the demo on built-in defaults in the project venv (created/refreshed by scripts/setup_env.sh if needed).
# Usage: bash scripts/demo.sh [bldc-actuator demo args...]     (bash scripts/demo.sh --help lists them)
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$(bash "$REPO/scripts/setup_env.sh")"

# Never let DDS discovery leave this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" ]]; then
    unset _ROS_WHEELS_BOOTSTRAP_COMPLETE LD_LIBRARY_PATH
fi
export MPLBACKEND="${MPLBACKEND:-Agg}"
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"

cd "$REPO"
exec "$VENV/bin/bldc-actuator" demo "$@"
