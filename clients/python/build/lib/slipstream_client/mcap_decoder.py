"""slipstream recordings through the `mcap` package's own decoding API.

    from mcap.reader import make_reader
    from slipstream_client.mcap_decoder import DecoderFactory

    with open("run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, (kind, header, body) in reader.iter_decoded_messages():
            ...

Each channel is decoded from its own schema record: schema encoding "slipstream-layout",
whose data is the layout of the channel's header and body (serde-reflection's registry format,
docs/recording.md), with postcard's rules (docs/wire-format.md). Nothing here is tied to this
client's wire version: a recording made by another version decodes as it was written.
Channels of other encodings (the viewable copies, ROS 2 channels) are left to other factories.
"""

import json
from typing import Any, Callable, Dict, List, Optional, Tuple

from .wire import WireError, _Reader

SCHEMA_ENCODING = "slipstream-layout"
MESSAGE_ENCODING_PREFIX = "slipstream/v"

# serde-reflection's primitive formats in the reader's type language.
_PRIMITIVES = {"U8": "u8", "U32": "u32", "U64": "u64", "I32": "i32", "F32": "f32", "F64": "f64",
               "BOOL": "bool", "STR": "str", "BYTES": "bytes"}

Decoded = Tuple[str, Dict[str, int], Dict[str, Any]]


class Layout:
    """One message type's layout, read from a schema record's data."""

    def __init__(self, data: bytes) -> None:
        try:
            doc = json.loads(data)
            self.wire_version: int = doc["wire_version"]
            self.kind_id: int = doc["kind"]
            self.name: str = doc["name"]
            self.header: str = doc["header"]
            self.body: str = doc["body"]
            registry: Dict[str, Any] = doc["registry"]
        except (ValueError, KeyError, TypeError) as e:
            raise WireError(f"not a {SCHEMA_ENCODING} schema: {e}") from None
        self.structs: Dict[str, List[Tuple[str, Any]]] = {}
        self.variants: Dict[str, List[Tuple[str, List[Tuple[str, Any]]]]] = {}
        self._registry = registry
        for name in (self.header, self.body):
            self._type(name)

    def decode(self, payload: bytes, copy: bool = True) -> Decoded:
        """(kind, header, body) of one payload, strictly: the version and kind bytes must be
        the layout's, and nothing may follow the body."""
        if len(payload) < 2:
            raise WireError("truncated in the preamble")
        if payload[0] != self.wire_version or payload[1] != self.kind_id:
            raise WireError(f"payload {payload[0]}/{payload[1]} is not of this channel's layout "
                            f"(wire version {self.wire_version}, kind {self.kind_id})")
        r = _Reader(payload, copy, self.structs, self.variants)
        r.at = 2
        header = r.read(("struct", self.header))
        body = r.read(("struct", self.body))
        if r.at != len(payload):
            raise WireError(f"{len(payload) - r.at} trailing bytes after a complete message")
        return self.name, header, body

    def _type(self, name: str) -> Any:
        """The reader's type for the registry's container `name` (described once)."""
        if name in self.structs:
            return ("struct", name)
        if name in self.variants:
            return ("variants", name)
        container = self._registry.get(name)
        if not isinstance(container, dict) or len(container) != 1:
            raise WireError(f"layout: type {name} is not described")
        (shape, inner), = container.items()
        if shape == "STRUCT":
            self.structs[name] = []  # a placeholder first: a type may contain itself
            self.structs[name] = self._fields(inner)
            return ("struct", name)
        if shape == "ENUM":
            cases = [next(iter(inner[str(i)].items())) for i in range(len(inner))]
            if all(v == "UNIT" for _, v in cases):
                return ("enum", [n for n, _ in cases])
            self.variants[name] = []
            self.variants[name] = [(n, self._variant_fields(n, v)) for n, v in cases]
            return ("variants", name)
        if shape == "NEWTYPESTRUCT":
            return self._format(inner)
        raise WireError(f"layout: {name} is a {shape}, which this reader does not decode")

    def _fields(self, fields: List[Dict[str, Any]]) -> List[Tuple[str, Any]]:
        return [(f, self._format(fmt)) for field in fields for f, fmt in field.items()]

    def _variant_fields(self, name: str, variant: Any) -> List[Tuple[str, Any]]:
        if variant == "UNIT":
            return []
        if isinstance(variant, dict) and "STRUCT" in variant:
            return self._fields(variant["STRUCT"])
        raise WireError(f"layout: variant {name} is {variant}, which this reader does not decode")

    def _format(self, fmt: Any) -> Any:
        if isinstance(fmt, str):
            if fmt not in _PRIMITIVES:
                raise WireError(f"layout: format {fmt} is not one this reader decodes")
            return _PRIMITIVES[fmt]
        (tag, inner), = fmt.items()
        if tag == "TYPENAME":
            return self._type(inner)
        if tag == "OPTION":
            return ("opt", self._format(inner))
        if tag == "SEQ":
            return ("seq", self._format(inner))
        if tag == "TUPLEARRAY":
            return ("arr", self._format(inner["CONTENT"]), inner["SIZE"])
        raise WireError(f"layout: format {tag} is not one this reader decodes")


try:
    from mcap.decoder import DecoderFactory as _Factory
    from mcap.records import Schema
except ImportError:  # the mcap package is not installed: the class still imports, unused
    _Factory = object  # type: ignore[assignment,misc]
    Schema = Any  # type: ignore[assignment,misc]


class DecoderFactory(_Factory):  # type: ignore[misc,valid-type]
    """Decodes the channels of slipstream's message encoding (`slipstream/vN`) whose schema
    is a slipstream layout, each message to (kind, header, body)."""

    def decoder_for(self, message_encoding: str, schema: Optional[Schema]) -> Optional[Callable[[bytes], Any]]:
        if not message_encoding.startswith(MESSAGE_ENCODING_PREFIX):
            return None
        if schema is None or schema.encoding != SCHEMA_ENCODING:
            return None
        return Layout(schema.data).decode
