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
"""

import os
import pathlib
import re

from .wire import DEFAULT_KEYS

_CHUNK = re.compile(r"^[A-Za-z0-9_\-.~+=,;:!'()]+$")


class ConfigError(ValueError):
    """A topic config the nodes would refuse: names the file, the key and the fix."""

    def __init__(self, origin, key, problem, fix):
        super().__init__(f"{origin}: key `{key}`: {problem}; fix: {fix}")


def _plain_key(origin, where, key):
    chunks = key.split("/")
    if not key or any(not c or not _CHUNK.match(c) for c in chunks):
        raise ConfigError(origin, where, f"`{key}` is not a plain Zenoh key",
                          "use chunks of letters, digits, `-` and `_` separated by `/`")
    return key


class Topics:
    """The key of every topic after namespace and remapping."""

    def __init__(self, namespace="", remap=None, origin="arguments"):
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
    def load(cls, path=None, namespace=None):
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
        remap = {}
        for topic, entry in (raw.get("topics") or {}).items():
            if topic not in DEFAULT_KEYS:
                raise ConfigError(origin, f"topics.{topic}", "no such topic",
                                  f"the topics are {', '.join(DEFAULT_KEYS)}")
            if isinstance(entry, dict) and "key" in entry:
                remap[topic] = entry["key"]
        return cls(namespace, remap, origin)

    def key(self, topic):
        """The key `topic` (a logical name such as "vehicle/speed") is published on."""
        try:
            return self._keys[topic]
        except KeyError:
            raise KeyError(f"no topic {topic!r}; the topics are {', '.join(DEFAULT_KEYS)}") from None

    def topic(self, key):
        """The logical topic published on `key`, or None."""
        return next((t for t, k in self._keys.items() if k == str(key)), None)

    def kind(self, key):
        """The message type published on `key`, or None."""
        topic = self.topic(key)
        return DEFAULT_KEYS[topic] if topic else None

    def node_key(self, name):
        """The liveliness token key of a node: `<namespace>/nodes/<name>`."""
        return f"{self.namespace}/nodes/{name}" if self.namespace else f"nodes/{name}"

    def all(self):
        """A key expression matching every key of this namespace."""
        return f"{self.namespace}/**" if self.namespace else "**"

    def items(self):
        return self._keys.items()


def parse_json5(text, origin="<json5>"):
    """The JSON5 the config files use: comments, unquoted keys, single quotes, trailing commas."""
    p = _Json5(text, origin)
    value = p.value()
    p.space()
    if p.i != len(text):
        p.fail("text after the end of the document")
    return value


class _Json5:
    def __init__(self, text, origin):
        self.s, self.i, self.origin = text, 0, origin

    def fail(self, what):
        line = self.s.count("\n", 0, self.i) + 1
        raise ConfigError(self.origin, f"line {line}", what, "write valid JSON5")

    def space(self):
        while self.i < len(self.s):
            if self.s[self.i].isspace():
                self.i += 1
            elif self.s.startswith("//", self.i):
                end = self.s.find("\n", self.i)
                self.i = len(self.s) if end < 0 else end
            elif self.s.startswith("/*", self.i):
                end = self.s.find("*/", self.i)
                if end < 0:
                    self.fail("unclosed comment")
                self.i = end + 2
            else:
                return

    def value(self):
        self.space()
        if self.i >= len(self.s):
            self.fail("unexpected end")
        c = self.s[self.i]
        if c == "{":
            return self.container("}", keyed=True)
        if c == "[":
            return self.container("]", keyed=False)
        if c in "\"'":
            return self.string()
        m = re.compile(r"[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+)|true|false|null|[A-Za-z_$][\w$]*").match(self.s, self.i)
        if not m:
            self.fail(f"unexpected {c!r}")
        self.i = m.end()
        word = m.group(0)
        if word in ("true", "false", "null"):
            return {"true": True, "false": False, "null": None}[word]
        try:
            return float(word) if any(ch in word for ch in ".eE") else int(word)
        except ValueError:
            self.fail(f"unexpected {word!r}")

    def string(self):
        quote, out = self.s[self.i], []
        self.i += 1
        while self.i < len(self.s) and self.s[self.i] != quote:
            if self.s[self.i] == "\\":
                self.i += 1
                out.append({"n": "\n", "t": "\t"}.get(self.s[self.i], self.s[self.i]))
            else:
                out.append(self.s[self.i])
            self.i += 1
        if self.i >= len(self.s):
            self.fail("unclosed string")
        self.i += 1
        return "".join(out)

    def container(self, close, keyed):
        self.i += 1
        out = {} if keyed else []
        while True:
            self.space()
            if self.s.startswith(close, self.i):
                self.i += 1
                return out
            if keyed:
                if self.s[self.i] in "\"'":
                    key = self.string()
                else:
                    m = re.compile(r"[A-Za-z_$][\w$]*").match(self.s, self.i)
                    if not m:
                        self.fail("expected a key")
                    key, self.i = m.group(0), m.end()
                self.space()
                if not self.s.startswith(":", self.i):
                    self.fail(f"expected `:` after {key!r}")
                self.i += 1
                out[key] = self.value()
            else:
                out.append(self.value())
            self.space()
            if self.s.startswith(",", self.i):
                self.i += 1
            elif not self.s.startswith(close, self.i):
                self.fail(f"expected `,` or `{close}`")
