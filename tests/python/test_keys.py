"""The Python client resolves keys exactly as the Rust nodes do (`slipstream info`), from the
same config files, namespaces and remapping."""

import json
import subprocess

import pytest
from conftest import ROOT

from slipstream_client import ConfigError, Topics
from slipstream_client.keys import parse_json5

REMAPPED = """// comments, unquoted keys, single quotes and trailing commas, as the nodes accept
{
  namespace: 'lab/rig2',
  topics: {
    "vehicle/speed": { key: "car/speed", priority: "real-time" },   // relative: under the namespace
    "objects": { key: '/fleet/truth', },                             /* absolute: no namespace */
  },
}
"""


def rust_keys(slipstream_bin, *flags):
    out = subprocess.run([slipstream_bin, "info", "--json", *flags], capture_output=True, text=True, timeout=30,
                         cwd=ROOT, check=True)
    return {t["topic"]: t["key"] for t in json.loads(out.stdout)["topics"]}


@pytest.mark.parametrize("namespace", [None, "car7"])
def test_keys_match_slipstream_info(slipstream_bin, tmp_path, namespace):
    config = tmp_path / "topics.json5"
    config.write_text(REMAPPED)
    flags = ["-t", str(config)] + (["-n", namespace] if namespace else [])
    rust = rust_keys(slipstream_bin, *flags)
    py = dict(Topics.load(str(config), namespace).items())
    assert py == rust
    assert py["objects"] == "fleet/truth"
    assert py["vehicle/speed"] == f"{namespace or 'lab/rig2'}/car/speed"
    # The shipped config spells out the defaults.
    assert dict(Topics.load(str(ROOT / "config" / "slipstream.json5")).items()) == rust_keys(slipstream_bin)


def test_bad_topic_configs_name_the_file_key_and_fix(tmp_path):
    bad = tmp_path / "bad.json5"
    bad.write_text('{ topics: { "vehicle/sped": { key: "x" } } }')
    with pytest.raises(ConfigError, match=r"bad.json5: key `topics.vehicle/sped`: no such topic; fix: the topics are"):
        Topics.load(str(bad))
    with pytest.raises(ConfigError, match=r"key `topics.vehicle/speed.key`: `car/\*\*` is not a plain Zenoh key"):
        Topics(remap={"vehicle/speed": "car/**"})
    with pytest.raises(ConfigError, match=r"key `line 3`: Unexpected \"}\" at column 1; fix: write valid JSON5"):
        parse_json5('{\n  a: [1, 2\n}')
    # JSON5 as the spec has it: escapes, hexadecimal numbers, infinities, trailing commas.
    assert parse_json5('{ a: "\\u00e9", b: 0x1f, c: -Infinity, d: [1, 2,], }') == {
        "a": "\u00e9", "b": 31, "c": float("-inf"), "d": [1, 2]}


def test_connection_flags_are_spelled_as_in_rust(slipstream_bin, tmp_path):
    """The same command line works for a Rust node and a Python client script."""
    import argparse

    from slipstream_client import connect

    cfg = tmp_path / "zenoh.json5"
    cfg.write_text('{ mode: "peer", scouting: { multicast: { enabled: true } }, listen: { endpoints: [] } }')
    parser = argparse.ArgumentParser()
    connect.add_args(parser)
    for spelled in ("-c", "--config"):
        argv = [spelled, str(cfg), "--no-multicast-scouting", "-m", "peer", "-e", "tcp/127.0.0.1:1",
                "--cfg", "scouting/gossip/enabled:true", "-n", "car7"]
        args = parser.parse_args(argv)
        assert (args.zenoh_config, args.no_multicast_scouting, args.namespace) == (str(cfg), True, "car7")
        # The Rust binary takes the very same flags.
        subprocess.run([slipstream_bin, "info", "--json", *argv], capture_output=True, text=True, timeout=30,
                       cwd=ROOT, check=True)
    conf = connect.zenoh_config(str(cfg), no_multicast_scouting=True)
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
