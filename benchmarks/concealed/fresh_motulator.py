"""A fresh-set recording made by a motulator version OTHER than the third-party set's (issue #24): motulator 0.17.1
in its own venv (``bash benchmarks/peers/setup2.sh`` -> ``.venv-peers2``; the peers venv has 0.18), driven in a
subprocess through the third-party set's motulator runner (:func:`.thirdparty_sim.simulate`: motulator's
``SynchronousMachine`` + ``MechanicalSystem`` + ``VoltageSourceConverter`` under its own ``CurrentVectorController``
(with its delay compensation) and ``SpeedController``), then converted here into the fresh set's run format: the
power-invariant d-q frame (× √(3/2)), the drive's 12-bit current ADC (noise, then quantization) and a 14-bit
encoder. Imports no bldc_actuator code.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SQRT3_2 = math.sqrt(1.5)
LIBRARIES: tuple[str, ...] = ()
KEYS = ("t", "i_ref", "i_meas", "u_ref", "w_M_meas", "u_dc", "theta_M", "w_M", "tau_M")


def python() -> Path:
    return Path(os.environ.get("BLDC_PEERS2_VENV", REPO / ".venv-peers2")) / "bin" / "python"


def motulator_version() -> str:
    """The motulator version of the second peer venv ("not installed" without it)."""
    try:
        out = subprocess.run([str(python()), "-c", "import importlib.metadata as m; print(m.version('motulator'))"],
                             capture_output=True, text=True, timeout=120)
        return out.stdout.strip() or "not installed"
    except OSError:
        return "not installed"


def simulate(spec: dict, duration: float, seed: int) -> dict:
    """One motulator run of ``spec`` (the third-party runner's plant / drive dicts) in the second peer venv; the
    fresh set's run dict (per control period, power-invariant d-q, ADC and encoder applied)."""
    with tempfile.TemporaryDirectory() as tmp:
        sp, out = Path(tmp) / "spec.json", Path(tmp) / "run.npz"
        sp.write_text(json.dumps({"plant": spec["plant"], "drive": spec["drive"]}))
        code = ("import sys, json, numpy as np; sys.path.insert(0, %r)\n"
                "from benchmarks.concealed import thirdparty_sim as T\n"
                "r = T.simulate(json.load(open(%r)), %r, %r)\n"
                "np.savez(%r, **{k: np.asarray(r[k]) for k in %r})\n") % (str(REPO), str(sp), float(duration),
                                                                          int(seed), str(out), KEYS)
        proc = subprocess.run([str(python()), "-c", code], capture_output=True, text=True, timeout=3600)
        if proc.returncode:
            raise RuntimeError(f"motulator run in {python()} failed: {proc.stderr.strip()[-600:]}")
        with np.load(out) as z:
            r = {k: z[k] for k in z.files}
    d = spec["drive"]
    rng = np.random.default_rng(seed + 7)
    n = len(r["t"])
    lsb, sd = d["adc_lsb"], d["adc_noise"]
    i_m = r["i_meas"] * SQRT3_2
    enc = 2 * math.pi / d["encoder_counts"]
    run = {"t": r["t"] - r["t"][0], "i_q_ref": (r["i_ref"] * SQRT3_2).imag, "i_q": i_m.imag, "i_d": i_m.real,
           "i_q_meas": lsb * np.round((i_m.imag + sd * rng.standard_normal(n)) / lsb),
           "i_d_meas": lsb * np.round((i_m.real + sd * rng.standard_normal(n)) / lsb),
           "v_q": (r["u_ref"] * SQRT3_2).imag, "v_d": (r["u_ref"] * SQRT3_2).real, "v_bus": r["u_dc"],
           "theta": r["theta_M"], "theta_enc": enc * np.round(r["theta_M"] / enc), "w_est": r["w_M_meas"],
           "w": r["w_M"], "tau_e": r["tau_M"]}
    return run


def job(args):
    name, spec, role, duration, seed = args
    t0 = time.perf_counter()
    run = simulate(spec, duration, seed)
    return name, role, run, time.perf_counter() - t0
