"""Topic keys in force, with the same rules as the Rust nodes (docs/wire-format.md, "Keys"):

- every topic's default key is its logical name (vehicle/speed, camera/front, ...);
- config/slipstream.json5 may remap it (`topics: { "vehicle/speed": { key: "car/speed" } }`);
  a remapped key with a leading "/" is absolute: the namespace does not apply to it;
- the namespace (config `namespace`, overridden by SLIPSTREAM_NAMESPACE or a flag) prefixes
  every relative key: "car1" turns vehicle/speed into car1/vehicle/speed.

    topics = Topics.load()                 # ./config/slipstream.json5 or $SLIPSTREAM_CONFIG
    topics = Topics(namespace="car1")      # no file
    topics.key("vehicle/speed")            # "car1/vehicle/speed"
    topics.kind("car1/vehicle/speed")      # "Speed"
    topics.read_key("camera/front")        # "car1/camera/front/@jpeg" with camera.read "jpeg"
"""

import os
import pathlib
import re

from typing import Any, Dict, ItemsView, Optional

import json5

from .wire import DEFAULT_KEYS

# camera.link_copies and camera.read name these (config/slipstream.json5).
FRAME_ENCODINGS = ("raw", "lz4", "jpeg", "png")

_CHUNK = re.compile(r"^[A-Za-z0-9_\-.~+=,;:!'()]+$")


class ConfigError(ValueError):
    """A topic config the nodes would refuse: names the file, the key and the fix."""

    def __init__(self, origin: str, key: str, problem: str, fix: str) -> None:
        super().__init__(f"{origin}: key `{key}`: {problem}; fix: {fix}")


def _plain_key(origin, where, key):
    chunks = key.split("/")
    if not key or any(not c or not _CHUNK.match(c) for c in chunks):
        raise ConfigError(origin, where, f"`{key}` is not a plain Zenoh key",
                          "use chunks of letters, digits, `-` and `_` separated by `/`")
    return key


class Topics:
    """The key of every topic after namespace and remapping."""

    def __init__(self, namespace: str = "", remap: Optional[Dict[str, str]] = None, origin: str = "arguments",
                 read: Optional[str] = None) -> None:
        if read not in (None, "published", *FRAME_ENCODINGS):
            raise ConfigError(origin, "camera.read", f"`{read}` is not a frame encoding",
                              'use "published" or a link copy: "raw", "lz4", "jpeg", "png"')
        self.read = None if read == "published" else read
        self.namespace = _plain_key(origin, "namespace", namespace.strip("/")) if namespace.strip("/") else ""
        self._keys = {}
        for topic in DEFAULT_KEYS:
            key = (remap or {}).get(topic, topic)
            absolute = key.startswith("/")
            rel = _plain_key(origin, f"topics.{topic}.key", key[1:] if absolute else key)
            self._keys[topic] = rel if absolute or not self.namespace else f"{self.namespace}/{rel}"
        unknown = set(remap or {}) - set(DEFAULT_KEYS)
        if unknown:
            raise ConfigError(origin, f"topics.{sorted(unknown)[0]}", "no such topic",
                              f"the topics are {', '.join(DEFAULT_KEYS)}")

    @classmethod
    def load(cls, path: Optional[str] = None, namespace: Optional[str] = None) -> "Topics":
        """Reads a slipstream topic config the way the nodes do: `path`, else $SLIPSTREAM_CONFIG,
        else ./config/slipstream.json5 when present, else the defaults. `namespace` (else
        $SLIPSTREAM_NAMESPACE) overrides the file's."""
        path = path or os.environ.get("SLIPSTREAM_CONFIG")
        if path is None and pathlib.Path("config/slipstream.json5").is_file():
            path = "config/slipstream.json5"
        raw, origin = {}, "built-in defaults"
        if path is not None:
            origin = str(path)
            try:
                text = pathlib.Path(path).read_text()
            except OSError as e:
                raise ConfigError(origin, "", f"cannot read it: {e.strerror}", "give an existing file") from None
            raw = parse_json5(text, origin)
            if not isinstance(raw, dict):
                raise ConfigError(origin, "", "the file is not an object", "write { namespace: ..., topics: {...} }")
        if namespace is None:
            namespace = os.environ.get("SLIPSTREAM_NAMESPACE", raw.get("namespace", ""))
            if not isinstance(namespace, str):
                raise ConfigError(origin, "namespace", f"{namespace!r} is not a string", "write e.g. namespace: 'car7'")
        remap = {}
        read = (raw.get("camera") or {}).get("read")
        for topic, entry in (raw.get("topics") or {}).items():
            if topic not in DEFAULT_KEYS:
                raise ConfigError(origin, f"topics.{topic}", "no such topic",
                                  f"the topics are {', '.join(DEFAULT_KEYS)}")
            if isinstance(entry, dict) and "key" in entry:
                remap[topic] = entry["key"]
        return cls(namespace, remap, origin, read)

    def key(self, topic: str) -> str:
        """The key `topic` (a logical name such as "vehicle/speed") is published on."""
        try:
            return self._keys[topic]
        except KeyError:
            raise KeyError(f"no topic {topic!r}; the topics are {', '.join(DEFAULT_KEYS)}") from None

    def copy_key(self, topic: str, encoding: str) -> str:
        """The key of a frame topic's link copy: `<key>/@<encoding>` (camera/front/@lz4). The
        "@" chunk is verbatim: wildcard subscriptions never match it."""
        if encoding not in FRAME_ENCODINGS:
            raise ValueError(f"{encoding!r} is not a frame encoding: {', '.join(FRAME_ENCODINGS)}")
        return f"{self.key(topic)}/@{encoding}"

    def read_key(self, topic: str) -> str:
        """The key to read `topic` from: a camera frame topic's link copy when the config's
        camera.read names one, else the topic's key (the same rule as the Rust nodes)."""
        if self.read is not None and DEFAULT_KEYS.get(topic) == "CameraFrame":
            return self.copy_key(topic, self.read)
        return self.key(topic)

    def topic(self, key: str) -> Optional[str]:
        """The logical topic published on `key`, or None."""
        return next((t for t, k in self._keys.items() if k == str(key)), None)

    def kind(self, key: str) -> Optional[str]:
        """The message type published on `key`, or None."""
        topic = self.topic(key)
        return DEFAULT_KEYS[topic] if topic else None

    def node_key(self, name: str) -> str:
        """The liveliness token key of a node: `<namespace>/nodes/<name>`."""
        return f"{self.namespace}/nodes/{name}" if self.namespace else f"nodes/{name}"

    def all(self) -> str:
        """A key expression matching every key of this namespace."""
        return f"{self.namespace}/**" if self.namespace else "**"

    def items(self) -> ItemsView[str, str]:
        return self._keys.items()


def parse_json5(text: str, origin: str = "<json5>") -> Any:
    """A JSON5 document (the config files' language) read with the `json5` package; an error
    names the file and the line."""
    try:
        return json5.loads(text)
    except ValueError as e:
        where = re.match(r"<string>:(\d+) (.*)", str(e))
        line, what = (f"line {where.group(1)}", where.group(2)) if where else ("", str(e))
        raise ConfigError(origin, line, what, "write valid JSON5") from None
