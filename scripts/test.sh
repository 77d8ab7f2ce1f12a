#!/usr/bin/env bash
# Run the test suite in the project venv (created/refreshed by scripts/setup_env.sh if needed).
# Usage: bash scripts/test.sh [pytest args...]     e.g.  bash scripts/test.sh -k frames -x
#        bash scripts/test.sh                       the whole suite: both passes below, on BLDC_TEST_WORKERS
#                                                   pytest-xdist workers (default 2; 0 = none; each worker gets
#                                                   its own ROS domain-id range, see test/conftest.py)
#        bash scripts/test.sh -n 0                  the whole suite in one process
#        bash scripts/test.sh -m "not slow"
# The cost of a run (wall, CPU, the slowest tests): python benchmarks/bench_suite.py [the same arguments]
set -euo pipefail
CALLER_DIR="$PWD"
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"   # (cd's to the repository)
set +e
# test paths given relative to the caller's directory stay the caller's; without any, the whole test/ tree
args=()
paths=0
for a in "$@"; do
    p="${a%%::*}"
    if [[ "$a" != -* && "$a" != /* && -e "$CALLER_DIR/$p" ]]; then
        args+=("$CALLER_DIR/$a"); paths=1
    elif [[ "$a" != -* && -e "$p" ]]; then
        args+=("$a"); paths=1
    else
        args+=("$a")
    fi
done
[[ $paths == 1 ]] || args=(test "${args[@]}")
# The physics kernel is compiled with numba; the same source also runs as plain Python
# (BLDC_ACTUATOR_NO_NUMBA=1). A full run (no test paths, -k or -m given) first runs the physics test files on
# that pure-Python path too, so every physics test runs on both paths (tests marked one_kernel_path, checks of
# the layers above the kernel such as a diagnosis round trip, run once: on the compiled path).
PHYSICS_FILES=(test/test_model.py test/test_simulate.py test/test_presets.py test/test_voltage_limit.py
               test/test_mujoco.py test/test_dead_time.py test/test_transmission.py)
both=1
for a in "$@"; do
    case "$a" in -k|-m|*test*|*::*) both=0 ;; esac
done
# A run of the whole tree (no test paths, no -k selection) spreads over pytest-xdist workers, whole files per
# worker (module fixtures computed once), unless the arguments choose (-n/--numprocesses/--dist, -p no:xdist)
# or BLDC_TEST_WORKERS=0.
workers=()
if [[ $paths == 0 && "${BLDC_TEST_WORKERS:-2}" != 0 ]]; then
    workers=(-n "${BLDC_TEST_WORKERS:-2}" --dist loadfile)
    for a in "$@"; do
        case "$a" in -k|-k*|-n|-n*|--numprocesses*|--dist*|no:xdist|-pno:xdist) workers=() ;; esac
    done
    "$VENV/bin/python" -c "import xdist" 2>/dev/null || workers=()
fi
rc=0
if [[ $both == 1 && "${BLDC_TEST_PYTHON_KERNEL:-1}" != 0 ]]; then
    echo "test.sh: physics tests on the pure-Python kernel path (BLDC_ACTUATOR_NO_NUMBA=1)"
    BLDC_ACTUATOR_NO_NUMBA=1 "$VENV/bin/python" -m pytest -q -p no:cacheprovider -m "not one_kernel_path" \
        "${workers[@]}" "${PHYSICS_FILES[@]}"
    rc=$?
    echo "test.sh: full suite (compiled kernel)"
fi
"$VENV/bin/python" -m pytest "${workers[@]}" "${args[@]}"
rc2=$?
[[ $rc -eq 0 ]] && rc=$rc2
set -e
if [[ $rc -eq 5 ]]; then
    # pytest: "no tests were collected" (e.g. a -k filter that matches nothing, or an empty suite)
    echo "test.sh: pytest collected no tests (exit 5); treating as success" >&2
    exit 0
fi
exit $rc
