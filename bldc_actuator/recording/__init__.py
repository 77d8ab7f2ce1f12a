"""MCAP recordings of the actuator: ROS 2 profile, CDR messages, parameters inside the file.

A recording alone is enough to re-simulate a run: the model parameters travel in a metadata record, and
every message is a ROS 2 CDR message under the schema, channel and QoS conventions of rosbag2's own MCAP
plugin (rosbag2_storage_mcap), which ``ros2 bag info/play`` (Jazzy and later) and Foxglove read. Verified
here: ``mcap_ros2`` and ``rosbags`` decode the files (``ros2 bag`` itself is not installable from PyPI).

Split the way ``rosbags`` splits its job, one module each:

- :mod:`.typesys`: message type names, ``ros2msg`` definitions, RIHS01 type hashes, message classes, QoS YAML;
- :mod:`.parameters`: the run's parameters as params-file YAML inside the file, and back;
- :mod:`.writer`: :class:`McapRecorder` (crash-safe chunks, full-disk handling, signal finalizer);
- :mod:`.reader`: :func:`read_raw` (records, undecoded), :func:`read_recording` (decoded),
  :func:`summarize`, :func:`parameters_from_recording`;
- :mod:`.foxglove`: a Foxglove layout for the topics and joints one recording holds.

Importing this package needs neither rclpy nor mcap; the writer and the decoders import them when used.
The full API and its guarantees: the docstrings of :mod:`.writer` and :mod:`.reader`.
"""

from __future__ import annotations

from .base import (DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_INTERVAL, LIBRARY, MCAP_MAGIC, MESSAGE_ENCODING, METADATA_NAME,
                   PARAMETERS_KEY, PROFILE, SCHEMA_ENCODING, RecorderClosedError, RecordingError,
                   RecordingWriteError)
from .parameters import parameters_from_yaml, render_parameters
from .reader import (RawRecording, Recording, as_level, parameters_from_recording, read_raw, read_recording,
                     summarize)
from .typesys import DEFAULT_QOS, interface_file, message_class, message_definition, qos_yaml, type_hash, type_name
from .writer import McapRecorder, install_signal_finalizer

__all__ = [
    "McapRecorder", "Recording", "RawRecording", "RecordingError", "RecorderClosedError", "RecordingWriteError",
    "install_signal_finalizer", "read_recording", "read_raw", "summarize", "parameters_from_recording",
    "message_definition", "message_class", "interface_file", "type_hash", "type_name", "qos_yaml",
    "render_parameters", "parameters_from_yaml", "as_level", "DEFAULT_CHUNK_SIZE", "DEFAULT_FLUSH_INTERVAL",
    "DEFAULT_QOS", "METADATA_NAME", "PARAMETERS_KEY", "PROFILE", "LIBRARY", "MCAP_MAGIC", "MESSAGE_ENCODING",
    "SCHEMA_ENCODING",
]
