"""Run a scenario script on one of the kernel's two paths (numba-compiled or plain Python) in a fresh interpreter:
the path is chosen at import time (``BLDC_ACTUATOR_NO_NUMBA``), so each path needs its own process. The script
prints a JSON object on stdout; its extra arguments arrive as ``sys.argv[1:]``."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from conftest import scaled


def run_on_kernel_path(script: str, *args: str, no_numba: bool) -> dict:
    env = dict(os.environ)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    env["BLDC_ACTUATOR_NO_NUMBA"] = "1" if no_numba else "0"
    done = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, env=env,
                          timeout=scaled(600))
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)
