#!/usr/bin/env bash
# Run the demo on built-in defaults in the project venv (created/refreshed by scripts/setup_env.sh if needed).
# Usage: bash scripts/demo.sh [bldc-actuator demo args...]     (bash scripts/demo.sh --help lists them)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
exec "$VENV/bin/bldc-actuator" demo "$@"
