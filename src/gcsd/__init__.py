"""gcsd: the vehicle side of MAVLink as an asyncio daemon."""

from importlib import metadata

try:
    __version__ = metadata.version("gcsd")
except metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.1.0"
