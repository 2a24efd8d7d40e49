"""Pure-Python client of slipstream's wire format (docs/wire-format.md)."""

from .wire import DEFAULT_KEYS, KINDS, WireError, decode, encode, encoding_schema

__all__ = ["DEFAULT_KEYS", "KINDS", "WireError", "decode", "encode", "encoding_schema"]
