"""bldc_actuator: a virtual BLDC/PMSM actuator (q-axis model) and a diagnosis tool.

The public API, importable from the package itself::

    import bldc_actuator as ba

    act = ba.Actuator(ba.load_preset("ak80_9"))          # one actuator; ba.BatchActuator for many
    result = ba.simulate_profile("ak80_9", ba.profiles.chirp(5.0, 1.0, 50.0, duration=2.0))
    i_q = ba.frames.current_q_from(10.0, "phase_peak", "wye")  # frame conversions (datasheet -> q axis)
    rec = ba.read_recording("run.mcap")                  # recordings: McapRecorder writes, read_* read
    report = ba.diagnose(signals, params)                # signals from ba.load_signals + ba.clean_signals

``import bldc_actuator`` stays light and ROS-free: every name is imported on first use (the physics kernel
compiles with numba, the recording decoders use rclpy or mcap_ros2, the diagnosis scipy). ``node`` (the ROS 2
node) is not part of this face: it needs rclpy.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: public name -> (module, attribute); attribute None: the module itself
_EXPORTS: dict[str, tuple[str, str | None]] = {
    # the model
    "Actuator": ("bldc_actuator.model", "Actuator"),
    "BatchActuator": ("bldc_actuator.model", "BatchActuator"),
    "SimResult": ("bldc_actuator.profiles", "SimResult"),
    # parameters and presets
    "ActuatorParams": ("bldc_actuator.params", "ActuatorParams"),
    "ParameterError": ("bldc_actuator.params", "ParameterError"),
    "load_yaml": ("bldc_actuator.params", "load_yaml"),
    "dump_yaml": ("bldc_actuator.params", "dump_yaml"),
    "load_preset": ("bldc_actuator.params", "load_preset"),
    "list_presets": ("bldc_actuator.params", "list_presets"),
    # frames, profiles, offline simulation
    "frames": ("bldc_actuator.frames", None),
    "profiles": ("bldc_actuator.profiles", None),
    "Profile": ("bldc_actuator.profiles", "Profile"),
    "simulate_profile": ("bldc_actuator.simulate", "simulate_profile"),
    # recordings
    "McapRecorder": ("bldc_actuator.recording", "McapRecorder"),
    "Recording": ("bldc_actuator.recording", "Recording"),
    "RecordingError": ("bldc_actuator.recording", "RecordingError"),
    "read_recording": ("bldc_actuator.recording", "read_recording"),
    "read_raw": ("bldc_actuator.recording", "read_raw"),
    "summarize_recording": ("bldc_actuator.recording", "summarize"),
    "parameters_from_recording": ("bldc_actuator.recording", "parameters_from_recording"),
    "resimulate": ("bldc_actuator.replay", "resimulate"),
    # diagnosis
    "load_signals": ("bldc_actuator.diagnosis.io.loaders", "load"),
    "clean_signals": ("bldc_actuator.diagnosis.io.cleaning", "clean"),
    "diagnose": ("bldc_actuator.diagnosis.pipeline", "diagnose"),
    "DiagnoseOptions": ("bldc_actuator.diagnosis.pipeline", "DiagnoseOptions"),
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> Any:
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'bldc_actuator' has no attribute {name!r}") from None
    mod = importlib.import_module(module)
    value = mod if attribute is None else getattr(mod, attribute)
    if attribute is not None:
        globals()[name] = value     # later look-ups skip __getattr__ (a submodule sets itself on import)
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
