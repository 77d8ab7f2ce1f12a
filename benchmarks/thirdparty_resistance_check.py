#!/usr/bin/env python3
"""Is the third-party set's ``tp_resistance`` (R × 1.4 with no load, ~0.08 A RMS of q current) fair?

A perfect-knowledge estimator: every parameter but R true (the nominal file's K, L, p; L_d = L_q), the q-axis
voltage equation ``v_q = R i_q + L di_q/dt + p ω L i_d + K ω`` on the LOGGED 1 kHz training channels, R by
least squares with the current command as instrument (the logged current's noise is in the regressor), its
standard error from the residual. Printed for the case and for ``tp_null`` (true R 0.13 Ω: what the same fit gives
there is the model's own error on a 1 kHz log of a 10 kHz drive), with the speed taken from the drive's logged
speed (its observer's estimate) or from the encoder angle (central difference), and the other channels delayed
against the logged voltage by 0-1.5 control periods (the drive applies a voltage one period after computing it and
holds it for one period in stator coordinates: it acts 1.5 periods after its sample, in a frame the rotor has turned
by p ω d since; the last column reads it so, as the diagnosis's voltage equation does), and the diagnosis's own
equation-error fit of the resistance (:func:`diagnosis_fit`).

    PYTHONPATH=. .venv-peers/bin/python benchmarks/thirdparty_resistance_check.py [CACHE_DIR ...]
    (default: benchmarks/.cache/thirdparty; the recordings of --set thirdparty)
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.concealed import thirdparty as T  # noqa: E402


def load(path: Path) -> dict[str, np.ndarray]:
    with path.open() as fh:
        rows = csv.reader(fh)
        head = next(rows)
        a = np.array([[float(x) for x in row] for row in rows])
    return {h: a[:, k] for k, h in enumerate(head)}


def fit_resistance(d: dict, K: float, L: float, p: int, *, speed: str = "encoder", delay_s: float = 0.0,
                   turn: bool = False, trim: int = 50) -> tuple[float, float]:
    """R [Ω] and its standard error from the logged channels, every other term of the q-axis equation true.
    ``turn``: the logged d/q voltage turned back by ``p ω delay_s`` as well (a voltage held in stator coordinates
    for ``delay_s`` after its sample: what the diagnosis does where the d axis shows that delay)."""
    t = d["time"]
    dt = float(t[1] - t[0])
    w = np.gradient(d["position"], t) if speed == "encoder" else d["velocity"]
    k = np.arange(len(t), dtype=float)

    def later(x):                                   # the channel at t + delay_s (linear interpolation)
        return np.interp(k + delay_s / dt, k, x)

    i_q, i_d, w = later(d["current"]), later(d["current_d"]), later(w)
    v_q = d["voltage_q"]
    if turn:
        phi = p * w * delay_s
        v_q = v_q * np.cos(phi) - d["voltage_d"] * np.sin(phi)
    r = v_q - (L * np.gradient(i_q, dt) + p * w * L * i_d + K * w)
    z = later(d["current_command"])
    s = slice(trim, len(t) - trim)
    R = float(np.sum(z[s] * r[s]) / np.sum(z[s] * i_q[s]))
    e = r[s] - R * i_q[s]
    se = float(np.std(e) * np.sqrt(np.sum(z[s] ** 2)) / abs(np.sum(z[s] * i_q[s])))
    return R, se


def diagnosis_fit(case_dir: Path) -> tuple[float, float, float]:
    """The diagnosis's own equation-error estimate: R [Ω], its sd and the voltage frame delay [s] it read from the d
    axis, from the search's resistance column (with its nuisance columns and the current command as instrument) on
    the training and held-out files against the nominal file, as ``diagnose`` prepares them."""
    from bldc_actuator.diagnosis.frame import candidates as cands
    from bldc_actuator.diagnosis.frame import equation_error as ee
    from bldc_actuator.diagnosis.io import cleaning, loaders
    from bldc_actuator.params import load_preset

    params = load_preset(str(case_dir / "params.yaml"))
    train, held = (cleaning.clean(loaders.load(str(case_dir / f), params=params), params=params)
                   for f in ("train.csv", "heldout.csv"))
    ctx = ee.prepare([(train, False), (held, True)], params)
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    cols["r_err"] = ctx.column("r_err", cands.col_r_err)
    fit = ee.fit_columns(ctx, cols, list(cols), {"electrical": 1.0}, blocks=["electrical"])
    return (params.motor.phase_resistance + float(fit.beta[-1]), float(np.sqrt(fit.cov[-1, -1])),
            float(ctx.sig.get("frame_delay", np.nan)))


def main(argv: list[str]) -> int:
    dirs = [Path(a) for a in argv] or [REPO / "benchmarks" / ".cache" / "thirdparty"]
    nom = T.nominal_params(T.get_case("tp_null"))
    K, L, p = nom.motor.torque_constant_q, nom.motor.q_inductance, nom.motor.pole_pairs
    delays = (0.0, 1.0e-4, 1.5e-4)
    print(f"{'recordings':22s} {'case':14s} {'true R':>7s} {'speed':8s} "
          + "  ".join(f"R at {1e6 * x:3.0f} µs delay" for x in delays)
          + "   150 µs, voltage turned back by p ω d")
    for base in dirs:
        for name in ("tp_resistance", "tp_null"):
            path = base / name / "train.csv"
            if not path.exists():
                continue
            d = load(path)
            true_R = T.simulation_spec(T.get_case(name))["plant"]["R_s"]
            for speed in ("logged", "encoder"):
                cells = [fit_resistance(d, K, L, p, speed=speed, delay_s=x) for x in delays]
                cells.append(fit_resistance(d, K, L, p, speed=speed, delay_s=1.5e-4, turn=True))
                print(f"{base.name:22s} {name:14s} {true_R:7.3f} {speed:8s} "
                      + "  ".join(f"{R:.4f} ± {se:.4f}     " for R, se in cells))
            R, se, fd = diagnosis_fit(base / name)
            print(f"{base.name:22s} {name:14s} {true_R:7.3f} the diagnosis's equation-error fit (speed from the encoder, "
                  f"voltage acting {1e6 * fd:.0f} µs after its sample, from the d axis): {R:.4f} ± {se:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
