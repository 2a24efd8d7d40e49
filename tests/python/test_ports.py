"""The tests' own ports (conftest.reserve_port): what keeps two tests running at once off each
other's loops."""

import socket

from conftest import FIRST_PORT, reserve_port


def test_reserved_ports_are_distinct_bindable_and_below_the_ephemeral_range():
    ports = [reserve_port() for _ in range(50)]
    assert len(set(ports)) == 50, ports
    assert all(FIRST_PORT <= p < 32768 for p in ports), ports
    with socket.socket() as s:
        s.bind(("127.0.0.1", ports[-1]))
