#!/usr/bin/env bash
# Run the demo on built-in defaults in the project venv (created/refreshed by scripts/setup_env.sh if needed).
# Usage: bash scripts/demo.sh [bldc-actuator demo args...]     (bash scripts/demo.sh --help lists them)
set -euo pipefail
CALLER_DIR="$PWD"
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
# relative --preset/--out paths are the user's: run from the directory the script was called from
cd "$CALLER_DIR"
exec "$VENV/bin/bldc-actuator" demo "$@"
