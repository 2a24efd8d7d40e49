"""Pure-Python client of slipstream's wire format (docs/wire-format.md) on eclipse-zenoh 1.10.

wire: decode/encode every message; keys: the keys in force after namespace and remapping;
connect: a Zenoh session with the nodes' flags; image: camera frames as numpy arrays;
simulator: the simulator side of docs/simulator-contract.md; camera: the pinhole of a
CameraInfo; mcap_decoder: recordings decoded by the `mcap` package from their own schemas;
cli: what command-line programs (examples, adapters) share. Library code raises
(WireError, ConfigError, connect.ConnectError) and logs to the "slipstream_client" logger; it
neither prints nor exits.
"""

from .keys import ConfigError, Topics
from .wire import DEFAULT_KEYS, KINDS, BadPayloads, WireError, decode, encode, encoding_schema

__all__ = [
    "DEFAULT_KEYS", "KINDS", "BadPayloads", "ConfigError", "Topics", "WireError", "decode", "encode", "encoding_schema",
]
