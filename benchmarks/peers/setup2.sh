#!/usr/bin/env bash
# A SECOND peer venv with a motulator version other than the peers venv's (issue #24's fresh set: the case
# fr_motulator017_resistance runs motulator 0.17.1 there, in a subprocess; .venv-peers has 0.18). Only numpy,
# scipy and motulator: the fresh set's motulator runner imports no bldc_actuator code. Usage:
#   bash benchmarks/peers/setup2.sh            -> prints the venv path (<repo>/.venv-peers2)
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="${BLDC_PEERS2_VENV:-$REPO/.venv-peers2}"
VERSION="${BLDC_PEERS2_MOTULATOR:-0.17.1}"
if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" ]]; then unset _ROS_WHEELS_BOOTSTRAP_COMPLETE LD_LIBRARY_PATH; fi
pick_python() {     # motulator >= 0.6 needs Python >= 3.12
    local c
    for c in "${BLDC_PEERS_PYTHON:-}" python3.13 python3.12 \
             $(ls -d "$(pyenv root 2>/dev/null || echo /nonexistent)"/versions/3.1[23]*/bin/python3 2>/dev/null); do
        [[ -n "$c" ]] || continue
        if "$c" -c 'import sys; sys.exit(sys.version_info < (3, 12))' 2>/dev/null; then echo "$c"; return; fi
    done
    echo "setup2.sh: no Python >= 3.12 found (set BLDC_PEERS_PYTHON)" >&2; exit 1
}
[[ -x "$VENV/bin/python" ]] || "$(pick_python)" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q "motulator==$VERSION" >&2
echo "$VENV"
