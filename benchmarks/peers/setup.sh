#!/usr/bin/env bash
# A SEPARATE venv for the physics peers (never dependencies of bldc_actuator): MuJoCo (its C <dcmotor>
# actuator), motulator, gym-electric-motor, plus this project. Usage:
#   bash benchmarks/peers/setup.sh            -> prints the venv path (<repo>/.venv-peers)
#   .venv-peers/bin/python benchmarks/bench_physics_peers.py
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="${BLDC_PEERS_VENV:-$REPO/.venv-peers}"
if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" ]]; then unset _ROS_WHEELS_BOOTSTRAP_COMPLETE LD_LIBRARY_PATH; fi
# motulator >= 0.6 (its current drive API, used by the third-party concealed set) needs Python >= 3.12: take the
# first interpreter that is (BLDC_PEERS_PYTHON, python3.13, python3.12, a pyenv 3.12/3.13), else python3
# (then pip resolves an old motulator and the motulator cases skip).
pick_python() {
    local c
    for c in "${BLDC_PEERS_PYTHON:-}" python3.13 python3.12 \
             $(ls -d "$(pyenv root 2>/dev/null || echo /nonexistent)"/versions/3.1[23]*/bin/python3 2>/dev/null) python3; do
        [[ -n "$c" ]] || continue
        if "$c" -c 'import sys; sys.exit(sys.version_info < (3, 12))' 2>/dev/null; then echo "$c"; return; fi
    done
    echo python3
}
if [[ -x "$VENV/bin/python" ]] && ! "$VENV/bin/python" -c 'import sys; sys.exit(sys.version_info < (3, 12))' \
        && [[ "$(pick_python)" != python3 ]]; then
    echo "setup.sh: $VENV has Python < 3.12; recreating it with $(pick_python)" >&2
    rm -rf "$VENV"
fi
[[ -x "$VENV/bin/python" ]] || "$(pick_python)" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip >&2
"$VENV/bin/python" -m pip install -q -e "$REPO[sim]" mujoco motulator gym-electric-motor pytest >&2
echo "$VENV"
