"""Opening a Zenoh session the way the slipstream nodes do, with the same flags.

Defaults match `slipstream up` on one machine: peer mode, connect to tcp/127.0.0.1:7447,
multicast scouting off (nothing leaves loopback). On a LAN pass `-e tcp/ROUTER:7447 -m client`,
or `-c config/lan-peer.json5` for multicast discovery, or any Zenoh config file with -c.

    parser = argparse.ArgumentParser()
    connect.add_args(parser)
    args = parser.parse_args()
    session, topics = connect.open_from_args(args)
"""

import argparse
import json
import os
from typing import Optional, Sequence, Tuple

import zenoh

from .keys import Topics

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


class ConnectError(ValueError):
    """A connection flag Zenoh refuses, or a session that cannot open: says which and why."""


def add_args(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("connection (same flags as the Rust nodes)")
    g.add_argument("-c", "--config", "--zenoh-config", dest="zenoh_config", metavar="FILE",
                   default=os.environ.get("SLIPSTREAM_ZENOH_CONFIG"),
                   help="Zenoh config file (JSON5) [env: SLIPSTREAM_ZENOH_CONFIG]; without it: peer mode on "
                        "loopback, scouting off")
    g.add_argument("-m", "--zenoh-mode", choices=["peer", "client"], help="Zenoh mode [default: peer]")
    g.add_argument("-e", "--connect", action="append", metavar="ENDPOINT", default=[],
                   help=f"endpoint to connect to, repeatable [default without -c: {DEFAULT_ENDPOINT}]")
    g.add_argument("-l", "--listen", action="append", metavar="ENDPOINT", default=[],
                   help="endpoint to listen on, repeatable [default: none]")
    g.add_argument("--no-multicast-scouting", action="store_true",
                   help="turn multicast scouting off (it is already off without -c)")
    g.add_argument("--cfg", action="append", metavar="KEY:VALUE", default=[],
                   help="any Zenoh config key, value in JSON5, e.g. --cfg 'transport/auth/usrpwd/user:\"acc\"'")
    g.add_argument("-t", "--topics", metavar="FILE",
                   help="topic config (namespace, key remapping) [default: $SLIPSTREAM_CONFIG, else "
                        "./config/slipstream.json5 if present]")
    g.add_argument("-n", "--namespace", help="put every key under this namespace [env: SLIPSTREAM_NAMESPACE]")


def zenoh_config(config_file: Optional[str] = None, mode: Optional[str] = None, connect: Sequence[str] = (),
                 listen: Sequence[str] = (), cfg: Sequence[str] = (), no_multicast_scouting: bool = False) -> zenoh.Config:
    """A zenoh.Config: the file, else loopback peer defaults; then mode, endpoints, scouting and
    --cfg pairs (the order the Rust nodes apply them in)."""
    if config_file:
        try:
            conf = zenoh.Config.from_file(config_file)
        except Exception as e:  # zenoh raises its own error type
            raise ConnectError(f"{config_file}: not a Zenoh config Zenoh takes: {e}") from None
    else:
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("listen/endpoints", "[]")
        conf.insert_json5("connect/endpoints", json.dumps(list(connect) or [DEFAULT_ENDPOINT]))
    if mode:
        conf.insert_json5("mode", json.dumps(mode))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if no_multicast_scouting:
        conf.insert_json5("scouting/multicast/enabled", "false")
    for kv in cfg:
        key, sep, value = kv.partition(":")
        if not sep:
            raise ConnectError(f"--cfg {kv!r}: missing `:` between key and value; write --cfg 'KEY:VALUE'")
        try:
            conf.insert_json5(key, value)
        except Exception as e:  # zenoh raises its own error type
            raise ConnectError(f"--cfg {kv!r}: rejected: {e}") from None
    return conf


def open_from_args(args: argparse.Namespace) -> Tuple[zenoh.Session, Topics]:
    """Opens the session and loads the topic keys from parsed `add_args` flags. Raises
    ConnectError (or keys.ConfigError for the topic config) with what to fix."""
    topics = Topics.load(args.topics, args.namespace)
    conf = zenoh_config(args.zenoh_config, args.zenoh_mode, args.connect, args.listen, args.cfg,
                        args.no_multicast_scouting)
    try:
        session = zenoh.open(conf)
    except Exception as e:  # zenoh raises its own error type
        where = ", ".join(args.connect) or args.zenoh_config or DEFAULT_ENDPOINT
        raise ConnectError(f"cannot open a Zenoh session ({where}): {e}") from None
    return session, topics
