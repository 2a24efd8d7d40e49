"""Every `--json` output and report is JSON a strict reader takes: no key twice in an object
(Python's json keeps the last of two, losing the first without a word; so do most readers)."""

import json
import subprocess
import time

from conftest import ROOT, reserve_port
from test_conform import Running


def strict(text):
    def refuse_repeats(pairs):
        keys = [k for k, _ in pairs]
        repeated = sorted({k for k in keys if keys.count(k) > 1})
        assert not repeated, f"keys {repeated} repeated in one object: {dict(pairs)}"
        return dict(pairs)

    return json.loads(text, object_pairs_hook=refuse_repeats)


def run(*argv, timeout=120):
    out = subprocess.run(list(argv), capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert out.stdout.strip(), f"{argv}: no output; stderr: {out.stderr[-2000:]}"
    return out.stdout


def test_every_json_output_has_each_key_once(slipstream_bin, sim_bin, free_port, tmp_path):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", "json"
    flags = ["-e", endpoint, "-l", "tcp/127.0.0.1:0", "-n", ns]
    strict(run(slipstream_bin, "info", "--json"))
    strict(run(slipstream_bin, "wire-examples"))
    strict(run(slipstream_bin, "ros2", "--list", "--json"))
    strict(run(slipstream_bin, "fuzz", "--count", "200", "--json"))
    strict(run(slipstream_bin, "eval", "detect", "--scenario", "cut-in", "--duration", "2", "--json"))
    strict(run(slipstream_bin, "eval", "acc", "--scenario", "steady-follow", "--perception", "ground-truth",
               "--duration", "3", "--json", timeout=300))
    demo = f"tcp/127.0.0.1:{reserve_port()}"
    strict(run(slipstream_bin, "-l", demo, "-e", demo, "-n", "json-demo", "demo", "--duration", "2", "--json"))
    with Running([sim_bin, "--scenario", "steady-follow", "--mode", "realtime", "--duration", "600", "-l", endpoint,
                  "-e", endpoint, "-n", ns]):
        time.sleep(1)
        rows = [strict(line) for line in run(slipstream_bin, *flags, "top", "--json", "--duration", "3").splitlines()]
        strict(run(slipstream_bin, *flags, "conform", "sim", "--json", "--duration", "1", "--no-control"))
    keys = {r["key"]: r for r in rows[-1]["keys"]}
    # A row names its key and the topic it is mapped to, each once.
    assert keys[f"{ns}/vehicle/speed"]["topic"] == "vehicle/speed", keys[f"{ns}/vehicle/speed"]
    sim_report = run(sim_bin, "--scenario", "steady-follow", "--mode", "fast", "--duration", "2", "--json",
                     "-l", "tcp/127.0.0.1:0", "-e", "tcp/127.0.0.1:1")
    strict(sim_report)
    report_dir = tmp_path / "report"
    subprocess.run([slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "-n", "json-up", "up", "--mode", "lockstep",
                    "--scenario", "steady-follow", "--duration", "3", "--plain", "--report", str(report_dir)],
                   capture_output=True, timeout=120, cwd=ROOT, check=True)
    report = strict((report_dir / "report.json").read_text())
    speed_rows = [r for r in report["topics"] if r["key"] == "json-up/vehicle/speed"]
    assert speed_rows and all(r["topic"] == "vehicle/speed" for r in speed_rows), speed_rows
