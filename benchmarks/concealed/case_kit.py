"""What the third-party case sets (:mod:`.thirdparty`: motulator, :mod:`.gem_cases`: gym-electric-motor) share:
case lookup and reseeding, the nominal file, the seeds of a case's recordings, the per-case recording key, the
CSV writer, the concealment record and the generate-or-reuse loop.

A case's files split into two kinds:

* its RECORDINGS (``train.csv``, ``heldout.csv`` and ``train_truth.npz``, the clean true signals of the training
  run that the concealment figure is computed from) are expensive (a peer simulator runs 7-17 s per simulated
  second). They are stamped (``.generator``) with :func:`recording_key`: the source of the set's simulation
  module (the only code that makes them), the functions that write them, the case's *recording spec* (the resolved plant, the drive's tuning from
  what it believes, the seeds, durations, log rate and sensors: everything the simulation reads and nothing
  else) and the library versions. They are simulated again only when that key moves.
* its TRUTH (``truth.json``: effects, true values, accepted aliases, story, concealment) and its NOMINAL file
  (``params.yaml``) are rewritten from the case definition on every run, without simulating: a scoring or truth
  edit, a corrected nominal field the simulated drive does not read, or a new case leaves every other case's
  recordings valid.
"""

from __future__ import annotations

import csv
import hashlib
import inspect
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Iterable

import numpy as np

RECORDINGS = ("train.csv", "heldout.csv", "train_truth.npz")
STAMP = ".generator"
#: what the generation of a case measured (wall seconds per recording), kept next to its recordings
GENERATION = "generation.json"


def find_case(cases: Iterable, name: str, label: str):
    cases = tuple(cases)
    for c in cases:
        if c.name == name:
            return c
    raise KeyError(f"no {label} case {name!r} (have: {', '.join(c.name for c in cases)})")


def reseeded(case, offset: int):
    """Fresh excitation and noise seeds (offset 0 = the published ones)."""
    return case if not offset else replace(case, seed=case.seed + 1000 * offset)


def nominal_params(base: dict, case):
    """The nominal parameter file of ``case``: the set's base with the case's flat overrides."""
    from bldc_actuator.params import from_flat

    values = dict(base)
    values.update(case.nominal)
    return from_flat(values)


def seeds(case) -> dict[str, int]:
    """Excitation seeds (``train``, ``heldout``) and sensor-noise seeds (``train_noise``, ``heldout_noise``)."""
    s = 1000 * case.seed
    return {"train": s + 1, "heldout": s + 2, "train_noise": s + 11, "heldout_noise": s + 12}


def library_version(dist: str) -> str:
    try:
        from importlib.metadata import version

        return version(dist)
    except Exception:   # noqa: BLE001
        return "not installed"


def code_stamp(module: ModuleType, libraries: Iterable[str], writers: Iterable[Callable] = ()) -> str:
    """Hash of what makes every recording of a set besides its own spec: the simulation module's source, the
    source of the functions that write its recordings (the set's ``write_recordings``; :func:`write_csv` and
    :func:`save_train_truth` always) and the versions of the libraries it runs on (numpy, scipy, the peer)."""
    h = hashlib.sha256(Path(module.__file__).read_bytes())
    for fn in (write_csv, save_train_truth, *writers):
        h.update(inspect.getsource(fn).encode())
    for lib in ("numpy", "scipy", *libraries):
        h.update(f"{lib}={library_version(lib)};".encode())
    return h.hexdigest()[:16]


def recording_key(spec: dict, module: ModuleType, libraries: Iterable[str], writers: Iterable[Callable] = ()) -> str:
    """The stamp of one case's recordings: :func:`code_stamp` and the case's recording spec (JSON, sorted keys)."""
    h = hashlib.sha256(code_stamp(module, libraries, writers).encode())
    h.update(json.dumps(spec, sort_keys=True, default=float).encode())
    return h.hexdigest()[:16]


def write_csv(path: Path, rec: dict, columns: Iterable[str]) -> None:
    cols = list(columns)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for i in range(len(rec["time"])):
            w.writerow([f"{rec[c][i]:.7g}" if c != "time" else f"{rec[c][i]:.5f}" for c in cols])


def concealment(case, effect_rms: float, current_noise: float, voltage_noise: float) -> dict:
    """The concealment record of ``truth.json``: the hidden effect's RMS in its channel next to the noise there."""
    noise = current_noise if case.channel == "current" else voltage_noise
    e = 0.0 if case.is_null else float(effect_rms)
    return {"channel": case.channel, "effect_rms": e, "noise_rms": noise, "snr": e / noise,
            "current": {"effect_rms": e if case.channel == "current" else 0.0, "noise_rms": current_noise},
            "voltage_q": {"effect_rms": e if case.channel == "voltage_q" else 0.0, "noise_rms": voltage_noise}}


def stale(case_dir: Path, key: str) -> bool:
    if not all((case_dir / f).exists() for f in RECORDINGS):
        return True
    stamp = case_dir / STAMP
    return not stamp.exists() or stamp.read_text().strip() != key


def ensure(cases, outdir: Path, *, key: Callable[[Any], str], simulate_job: Callable, write_recordings: Callable,
           write_truth: Callable, label: str, regenerate: bool = False,
           progress: Callable[[str], None] | None = None, workers: int = 2) -> tuple[dict, list[str]]:
    """Simulate the cases whose recordings are missing or stamped with another key (all with ``regenerate``),
    then rewrite every case's ``params.yaml`` and ``truth.json`` from its definition.

    ``simulate_job((case, role, duration, seed))`` -> (name, role, run, seconds) runs in a worker process;
    ``write_recordings(case, runs_by_role, case_dir)`` writes the recordings; ``write_truth(case, case_dir)``
    -> truth dict. Returns ``({name: truth}, [names simulated])``."""
    outdir = Path(outdir)
    todo = [c for c in cases if regenerate or stale(outdir / c.name, key(c))]
    if todo:
        jobs = []
        for c in todo:
            s = seeds(c)
            jobs += [(c, "train", c.train_s, s["train"]), (c, "heldout", c.heldout_s, s["heldout"])]
        runs: dict = {}
        secs: dict = {}
        t0 = time.perf_counter()
        if progress:
            progress(f"simulating {len(todo)} case(s) with {label}: {', '.join(c.name for c in todo)}")
        with ProcessPoolExecutor(max_workers=workers) if workers > 1 else _InProcess() as ex:
            for k, (name, role, run, dt) in enumerate(ex.map(simulate_job, jobs), start=1):
                runs[(name, role)] = run
                secs[(name, role)] = dt
                if progress:
                    progress(f"simulated {k}/{len(jobs)} recordings with {label} "
                             f"({time.perf_counter() - t0:.0f} s)")
        for c in todo:
            d = outdir / c.name
            d.mkdir(parents=True, exist_ok=True)
            (d / STAMP).unlink(missing_ok=True)
            write_recordings(c, {r: runs[(c.name, r)] for r in ("train", "heldout")}, d)
            (d / GENERATION).write_text(json.dumps(
                {"seconds": {r: secs[(c.name, r)] for r in ("train", "heldout")}, "key": key(c)}, indent=2) + "\n")
            (d / STAMP).write_text(key(c))
    truths = {c.name: write_truth(c, outdir / c.name) for c in cases}
    return truths, [c.name for c in todo]


class _InProcess:
    """``workers <= 1``: simulate in this process (tests, debugging)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    @staticmethod
    def map(fn, items):
        return map(fn, items)


def save_train_truth(path: Path, **signals: np.ndarray) -> None:
    """The clean true signals of a training run (control rate) that the truth's concealment figure needs."""
    np.savez_compressed(path, **{k: np.asarray(v) for k, v in signals.items()})


def load_train_truth(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def write_truth(case, case_dir: Path, nominal, *, label: str, source: str, specifics: dict,
                concealment: Callable[[Any, dict, Any], dict], torque_sensor: bool = False) -> dict:
    """A third-party case's ``params.yaml`` (``nominal``, the user's belief) and ``truth.json`` from its definition
    and the training run's stored clean signals (no simulation); ``specifics``: the set's own truth fields
    (written after ``source``), ``concealment(case, signals, nominal)``: its hidden-term record."""
    from bldc_actuator.params import dump_yaml

    dump_yaml(nominal, case_dir / "params.yaml", header=f"{label} concealed case {case.name}: the NOMINAL model")
    sig = load_train_truth(case_dir / "train_truth.npz")
    s = seeds(case)
    truth = {
        "case": case.name, "effects": list(case.effects), "story": case.story, "truth": case.truth,
        "alias_ok": {k: list(v) for k, v in case.alias_ok.items()},
        "not_decidable": list(getattr(case, "not_decidable", ())), "source": source, **specifics,
        "concealment": concealment(case, sig, nominal), "oracle": None,
        "recording_key": (case_dir / STAMP).read_text().strip(), "generation_seconds": generation_seconds(case_dir),
        "train": {"excitation": "speed: triangle + multisine", "duration_s": case.train_s, "seed": s["train"]},
        "heldout": {"excitation": "speed: triangle + multisine", "duration_s": case.heldout_s, "seed": s["heldout"]},
        "log": {"rate": case.log_rate, "filter": "sample", "torque_sensor": torque_sensor},
        "ranges": {"max_abs_velocity_motor_rad_s": float(np.max(np.abs(sig["w"]))),
                   "max_abs_current_A": float(np.max(np.abs(sig["i_q"])))},
    }
    (case_dir / "truth.json").write_text(json.dumps(truth, indent=2, default=float) + "\n")
    return truth


def generation_seconds(case_dir: Path) -> float | None:
    p = case_dir / GENERATION
    if not p.exists():
        return None
    return float(sum(json.loads(p.read_text())["seconds"].values()))
