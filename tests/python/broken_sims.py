"""Simulators that break one rule of the contract each: the Python reference simulator with
one method changed. `python broken_sims.py NAME [reference_sim flags]` runs one of them, so
that `slipstream conform sim` can be shown to fail naming the rule."""

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "clients" / "python" / "examples"))

import reference_sim  # noqa: E402
from reference_sim import ReferenceSim  # noqa: E402

from slipstream_client.simulator import SimulatorSide  # noqa: E402


class NoCamera(ReferenceSim):
    """Leaves out a required key: camera/front (and its ground truth)."""

    def publish_frame(self, k):
        pass


class SpeedAt10Hz(SimulatorSide):
    """Publishes vehicle/speed at 10 Hz while everything else runs at 100 Hz."""

    def put(self, topic, kind, k, body):
        if topic == "vehicle/speed" and k % 10:
            return
        super().put(topic, kind, k, body)


class StampsBackwards(SimulatorSide):
    """Simulated time jumps back by a second every 50 steps."""

    def stamp(self, k):
        return max(0, super().stamp(k) - (1_000_000_000 if k % 50 == 49 else 0))


class InfoNotLatched(SimulatorSide):
    """Sends the camera info once with a plain publisher: a late subscriber never gets it."""

    def latched(self, topic):
        return self.session.declare_publisher(self.topics.key(topic))


class IgnoresControl(SimulatorSide):
    """Never applies vehicle/control (reports the neutral command)."""

    def command_for(self, k):
        return None, None


class NoLockstepWait(SimulatorSide):
    """Says Lockstep on sim/clock but never waits for the controller's answer."""

    def await_answer(self, k):
        return None, None

    def wait_for_controllers(self):
        pass


BROKEN = {cls.__name__: cls for cls in (NoCamera, SpeedAt10Hz, StampsBackwards, InfoNotLatched, IgnoresControl,
                                        NoLockstepWait)}

if __name__ == "__main__":
    broken = BROKEN[sys.argv.pop(1)]
    if issubclass(broken, ReferenceSim):
        sys.exit(reference_sim.main(sim_class=broken))
    sys.exit(reference_sim.main(side_class=broken))
