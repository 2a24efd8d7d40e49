"""What a person at a terminal sees, through a pseudo-terminal (`script`): colour on a terminal
and none with NO_COLOR set (no-color.org); no control characters at all when stderr is a pipe."""

import os
import shutil
import subprocess

import pytest

from conftest import ROOT

SCRIPT = shutil.which("script")
ESC = "\x1b["


def echo_for_a_second(slipstream_bin, free_port, env, tty):
    cmd = [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "echo", "vehicle/speed", "--duration", "1"]
    if tty:
        # util-linux script: the command on a pseudo-terminal, its output on our stdout.
        cmd = [SCRIPT, "-qc", " ".join(cmd), "/dev/null"]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=60, cwd=ROOT, env=env)
    return run.stdout + run.stderr


@pytest.mark.skipif(SCRIPT is None, reason="no `script` (util-linux) for a pseudo-terminal")
def test_colour_only_on_a_terminal_and_never_with_no_color(slipstream_bin, free_port):
    # Tools log warnings only by default; RUST_LOG=info shows their "joined the bus" line.
    env = {**{k: v for k, v in os.environ.items() if k != "NO_COLOR"}, "RUST_LOG": "info"}
    on_tty = echo_for_a_second(slipstream_bin, free_port, env, tty=True)
    assert "joined the bus" in on_tty and ESC in on_tty, on_tty[-1000:]
    no_color = echo_for_a_second(slipstream_bin, free_port, {**env, "NO_COLOR": "1"}, tty=True)
    assert "joined the bus" in no_color and ESC not in no_color, no_color[-1000:]
    piped = echo_for_a_second(slipstream_bin, free_port, env, tty=False)
    assert "joined the bus" in piped and ESC not in piped, piped[-1000:]
