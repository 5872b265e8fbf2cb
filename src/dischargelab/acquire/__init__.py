"""Data acquisition: the Arduino logger protocol, serial transport, producer/consumer
pipeline, safety cutoffs, live view and a virtual device for testing without hardware.

Importing this package imports neither pyserial nor matplotlib; they are loaded
when a port is opened or a plot window is requested.
"""

from .pipeline import (
    EXIT_STATUS,
    Consumer,
    Pipeline,
    ReconnectPolicy,
    Sample,
    SampleSource,
    SourceDisconnected,
)
from .sources import SOURCE_KINDS, open_source, register_source

__all__ = [
    "Sample", "SampleSource", "Consumer", "SourceDisconnected", "Pipeline", "ReconnectPolicy",
    "EXIT_STATUS", "open_source", "register_source", "SOURCE_KINDS",
]
