"""A detector that breaks the node contract on purpose, for tests/python/test_own_detector.py:

    python3 bad_detectors.py crash      # answers three frames, then raises
"""

import sys

from slipstream_client.detector import run_detector

seen = []


def crash(frame):
    seen.append(frame.seq)
    if len(seen) > 3:
        raise RuntimeError("the network's weights did not load")
    return []


if __name__ == "__main__":
    mode = sys.argv.pop(1)
    run_detector({"crash": crash}[mode])
