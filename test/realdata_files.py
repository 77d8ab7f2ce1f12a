"""Names for the real recordings in ``../shared/data`` (tests and benchmarks only; the product holds no
dataset knowledge: every file is read by the input profile its header matches).

``list_datasets(shared)`` -> [DatasetInfo]; ``load_dataset(name, shared, clean=True)`` reads the file (or,
for a folder name, all its files as segments) with :func:`bldc_actuator.diagnosis.io.loaders.load` /
:func:`~bldc_actuator.diagnosis.io.loaders.load_many` and auto-detected profiles, then cleans it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path


@dataclass
class DatasetInfo:
    name: str          # e.g. "ak80-9/sysid_final/trial5"
    path: str          # the file (or folder for combined sets)
    kind: str          # "time_series" | "steady_state_points"
    licence: str


def data_dir(shared_dir: str | Path | None = None) -> Path:
    """``shared_dir`` may be ``shared/`` or its ``data/``; default ``$BLDC_SHARED_DIR`` or ``<repo>/../shared``."""
    if shared_dir is None:
        env = os.environ.get("BLDC_SHARED_DIR")
        shared_dir = Path(env) if env else Path(__file__).resolve().parents[2] / "shared"
    p = Path(shared_dir)
    if (p / "data").is_dir():
        p = p / "data"
    if not p.is_dir():
        raise FileNotFoundError(f"shared data folder not found: {p}")
    return p


def _licence(folder: Path) -> str:
    try:
        for line in (folder / "SOURCE.txt").read_text().splitlines():
            if line.upper().startswith(("LICENCE", "LICENSE")):
                return line.split(":", 1)[1].strip().split(" (")[0].split(";")[0].strip().rstrip(".")
    except OSError:
        pass
    return "unknown"


def _entries(root: Path) -> list[tuple[DatasetInfo, list[Path]]]:
    out = []
    ak = root / "ak80-9"
    if ak.is_dir():
        lic = _licence(ak)
        for sub in ("sysid_final", "sysid_early", "torque_performance_max_curr", "no_torque_tests"):
            for f in sorted((ak / sub).glob("**/*.csv")):
                stem = f.parent.name if f.name == "log_adc_and_motor.csv" else f.stem
                out.append((DatasetInfo(f"ak80-9/{sub}/{stem}", str(f), "time_series", lic), [f]))
        for d in sorted((ak / "torque_vs_angle").glob("synchronized_trial_*")):
            files = sorted(d.glob("test-opposing-motor*.csv"))
            if files:
                out.append((DatasetInfo(f"ak80-9/torque_vs_angle/{d.name}", str(files[0]), "time_series", lic),
                            files[:1]))
        eff = sorted((ak / "servo_efficiency").glob("Measuring_efficiency_*.csv"))
        if eff:
            out.append((DatasetInfo("ak80-9/servo_efficiency", str(ak / "servo_efficiency"), "time_series", lic), eff))
            for f in eff:
                out.append((DatasetInfo(f"ak80-9/servo_efficiency/{f.stem.rsplit('antagonist', 1)[-1]}", str(f),
                                        "time_series", lic), [f]))
        for f in sorted((ak / "mit_control_mode_tests").glob("*/log.csv")):
            out.append((DatasetInfo(f"ak80-9/mit_control_mode_tests/{f.parent.name}", str(f), "time_series", lic), [f]))
        for f in sorted((ak / "servo_static_torque").glob("torque_test_script_*_A.csv")):
            out.append((DatasetInfo(f"ak80-9/servo_static_torque/{f.stem.replace('torque_test_script_', '')}",
                                    str(f), "time_series", lic), [f]))
    od = root / "odrive-d5065" / "odrive_data.csv"
    if od.exists():
        out.append((DatasetInfo("odrive-d5065/odrive_data", str(od), "steady_state_points", _licence(od.parent)), [od]))
    bk = root / "benkatz-dyno"
    for f in sorted(bk.glob("*.csv")) if bk.is_dir() else []:
        out.append((DatasetInfo(f"benkatz-dyno/{f.stem}", str(f), "time_series", _licence(bk)), [f]))
    return out


def list_datasets(shared_dir: str | Path | None = None) -> list[DatasetInfo]:
    return [info for info, _ in _entries(data_dir(shared_dir))]


def load_dataset(name: str, shared_dir: str | Path | None = None, *, clean: bool = True, params=None):
    from bldc_actuator.diagnosis.io import loaders
    from bldc_actuator.diagnosis.io.cleaning import clean as _clean

    entries = _entries(data_dir(shared_dir))
    for info, files in entries:
        if info.name == name:
            sig = loaders.load(files[0], params=params) if len(files) == 1 and Path(info.path).is_file() \
                else loaders.load_many(files, params=params)
            sig.meta["dataset_name"] = name
            return _clean(sig, params=params) if clean else sig
    raise KeyError(f"no dataset named {name!r} ({len(entries)} known: see list_datasets())")
