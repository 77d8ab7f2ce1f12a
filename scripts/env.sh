# Sourced by scripts/demo.sh and scripts/test.sh: sets REPO and VENV (created/refreshed by setup_env.sh)
# and the environment every run of this project needs.
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$(bash "$REPO/scripts/setup_env.sh")"

# Never let DDS discovery leave this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# ...and keep the DDS sockets on loopback (LOCALHOST alone binds them to 0.0.0.0 and the external interface)
export FASTDDS_DEFAULT_PROFILES_FILE="$REPO/config/fastdds_localhost.xml"
# The venv's interpreter bootstraps its own LD_LIBRARY_PATH; drop another ROS-wheels venv's state.
if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" ]]; then
    unset _ROS_WHEELS_BOOTSTRAP_COMPLETE LD_LIBRARY_PATH
fi
export MPLBACKEND="${MPLBACKEND:-Agg}"
# numpy's OpenBLAS thread pool makes small products far slower on a busy 2-core machine
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
cd "$REPO"
