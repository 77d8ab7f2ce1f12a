#!/usr/bin/env bash
# A SEPARATE venv for the physics peers (never dependencies of bldc_actuator): MuJoCo (its C <dcmotor>
# actuator), motulator, gym-electric-motor, plus this project. Usage:
#   bash benchmarks/peers/setup.sh            -> prints the venv path (<repo>/.venv-peers)
#   .venv-peers/bin/python benchmarks/bench_physics_peers.py
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="${BLDC_PEERS_VENV:-$REPO/.venv-peers}"
if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" ]]; then unset _ROS_WHEELS_BOOTSTRAP_COMPLETE LD_LIBRARY_PATH; fi
[[ -x "$VENV/bin/python" ]] || python3 -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip >&2
"$VENV/bin/python" -m pip install -q -e "$REPO[sim]" mujoco motulator gym-electric-motor >&2
echo "$VENV"
