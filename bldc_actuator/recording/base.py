"""Constants and errors shared by the recording writer and reader (the file conventions in one place)."""

from __future__ import annotations

from .. import __version__

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_NAME = "bldc_actuator"
PARAMETERS_KEY = "parameters_yaml"
LIBRARY = f"bldc_actuator {__version__}"
DEFAULT_CHUNK_SIZE = 256 * 1024
DEFAULT_FLUSH_INTERVAL = 1.0
MCAP_MAGIC = b"\x89MCAP0\r\n"
#: keys of the metadata record written by the recorder itself (user metadata may not use them)
RESERVED_METADATA_KEYS = frozenset({PARAMETERS_KEY, "record", "finalized_by", "messages_written",
                                    "last_time_ns", "recorder", "parameters_error"})



class RecordingError(Exception):
    """A recording cannot be read: missing file, not MCAP, or required content absent."""


class RecorderClosedError(RuntimeError):
    """write()/add_topic() after close()."""


class RecordingWriteError(OSError):
    """Writing to the file failed (disk full, I/O error, file system gone). The recording has stopped: the
    file was cut back to its last complete chunk (readable, unfinalized) and further writes raise
    :class:`RecorderClosedError`. ``errno``/``strerror`` are those of the failed write."""

