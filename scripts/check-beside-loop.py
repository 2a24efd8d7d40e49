"""Judges the loop scripts/test.sh keeps running beside the tests: it must have stayed in the
default namespace, been stopped by the test command's signal (exit 130), lost no node, and
taken no input from any test: no command reached its simulator from another node than its own
ACC, and no test's sample reached its ACC (a test's node that dialled the machine's rendezvous
would show here). Prints what it found; exit 1 on anything else.

    python3 scripts/check-beside-loop.py REPORT_DIR EXIT_CODE
"""

import json
import pathlib
import sys


def problems(report_dir, code):
    found = []
    if code != 130:
        found.append(f"exit code {code}, not 130 (stopped by the test command's SIGINT)")
    report = json.loads((report_dir / "report.json").read_text())
    if report["namespace"] != "":
        found.append(f"it ran in namespace {report['namespace']!r}, not the default one")
    if not report["interrupted"]:
        found.append("it ended before the test command stopped it")
    died = [n["node"] for n in report["nodes"] if n["died"]]
    if died:
        found.append(f"nodes died: {died}")
    if report["collisions"]:
        found.append(f"{report['collisions']} collisions")
    sim = json.loads((report_dir / "logs" / "slipstream-sim.json").read_text())
    if sim.get("control_foreign"):
        found.append(f"its simulator saw {sim['control_foreign']} commands from another node than its ACC")
    acc = json.loads((report_dir / "logs" / "slipstream-acc.json").read_text())
    if acc.get("foreign_inputs"):
        found.append(f"its ACC saw {acc['foreign_inputs']} samples from another publisher than its simulator")
    print(f"beside loop: {report['sim_time_s']:.0f} s simulated in the default namespace, "
          f"{len(report['nodes'])} nodes, {sim.get('control_foreign', 0)} foreign commands, "
          f"{acc.get('foreign_inputs', 0)} foreign inputs")
    return found


def main():
    report_dir, code = pathlib.Path(sys.argv[1]), int(sys.argv[2])
    found = problems(report_dir, code)
    for p in found:
        print(f"beside loop: {p}", file=sys.stderr)
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
