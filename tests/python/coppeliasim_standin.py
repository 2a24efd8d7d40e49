"""A stand-in for CoppeliaSim's ZMQ remote API server: answers, on a ZMQ REP socket in CBOR as
the add-on does, the `sim` calls the adapter makes (clients/python/adapters/coppeliasim_adapter.py),
for a scene of standin_world's road: /Car (the ego, whose child script has
slipstream_control), /Car/visionSensor (640x480, 60 degrees, 1.35 m up, pitched 3 degrees
down), /Lead and /Other. The adapter talks to it with CoppeliaSim's own client package,
unchanged. Nothing of CoppeliaSim runs here.

    python tests/python/coppeliasim_standin.py PORT          # serve until killed

STANDIN_DIE_AFTER=S: the server stops answering after S simulated seconds."""

import math
import os
import sys
import threading
import time

import cbor
import numpy as np
import zmq
from standin_world import CAR_REAR_OVERHANG, HALF_LENGTH, camera, draw, road_world

DT = 0.01  # the scene's time step
REAR_AXLE = HALF_LENGTH - CAR_REAR_OVERHANG  # model origin (centre) to rear axle
MOUNT = (1.6 - REAR_AXLE, 0.0, 1.35)  # the vision sensor relative to /Car
PITCH = math.radians(3.0)
CONSTANTS = {"handle_world": -1, "handle_scene": -2, "scripttype_childscript": 1,
             "visionfloatparam_perspective_angle": 1004}
FUNCTIONS = ["getSimulationTimeStep", "getObject", "getScript", "getVisionSensorImg", "getObjectFloatParam",
             "getObjectPosition", "getObjectOrientation", "getObjectMatrix", "getObjectVelocity",
             "callScriptFunction", "setStepping", "startSimulation", "stopSimulation", "step", "getSimulationTime"]


class Scene:
    def __init__(self):
        self.movers = road_world()
        self.handles = {"/Car": 10, "/Car/visionSensor": 11, "/Lead": 12, "/Other": 13}
        self.by_handle = {10: self.movers[0], 12: self.movers[1], 13: self.movers[2]}
        self.camera = camera(640, 480, 60.0, (1.6, 0.0, 1.35), 3.0)
        self.t, self.stepping, self.running, self.lock = 0.0, False, False, threading.Lock()
        self.die_after = float(os.environ.get("STANDIN_DIE_AFTER", "inf"))
        threading.Thread(target=self.free_run, daemon=True).start()

    def advance(self):
        with self.lock:
            for m in self.movers:
                m.step(self.t, DT)
            self.t += DT

    def free_run(self):
        """Not stepping: the simulation runs at the wall clock, as CoppeliaSim in real-time mode."""
        while True:
            time.sleep(DT)
            if self.running and not self.stepping:
                self.advance()

    # The `sim` functions, by name; each returns the list of return values.
    def getSimulationTimeStep(self):
        return [DT]

    def getObject(self, path):
        if path not in self.handles:
            raise KeyError(f"object does not exist: {path}")
        return [self.handles[path]]

    def getScript(self, kind, handle):
        return [100 + handle]

    def getVisionSensorImg(self, handle):
        with self.lock:
            rgb = draw(self.camera, self.movers)
        return [np.ascontiguousarray(rgb[::-1]).tobytes(), [640, 480]]  # bottom row first

    def getObjectFloatParam(self, handle, param):
        return [math.radians(60.0)]

    def getObjectPosition(self, handle, relative_to):
        if handle == 11:
            return [list(MOUNT)] if relative_to == 10 else [[self.movers[0].x + MOUNT[0], self.movers[0].y, 1.35]]
        m = self.by_handle[handle]
        return [[m.x, m.y, 0.0]]

    def getObjectOrientation(self, handle, relative_to):
        return [[0.0, 0.0, 0.0]]

    def getObjectMatrix(self, handle, relative_to):
        # The sensor looks along its z axis: forward and PITCH below the horizon.
        z = (math.cos(PITCH), 0.0, -math.sin(PITCH))
        x = (0.0, -1.0, 0.0)
        y = (z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0])
        return [[x[0], y[0], z[0], MOUNT[0], x[1], y[1], z[1], MOUNT[1], x[2], y[2], z[2], MOUNT[2]]]

    def getObjectVelocity(self, handle):
        m = self.by_handle[handle]
        return [[m.v, 0.0, 0.0], [0.0, 0.0, 0.0]]

    def callScriptFunction(self, name, script, throttle, brake, steer):
        if name != "slipstream_control" or script != 110:
            raise KeyError(f"no function {name} in script {script}")
        self.movers[0].command = (throttle, brake)
        return []

    def setStepping(self, enable):
        self.stepping = bool(enable)
        return [0]

    def startSimulation(self):
        self.running = True
        return [1]

    def stopSimulation(self):
        self.running = False
        return [1]

    def step(self, wait=True):
        self.advance()
        return []

    def getSimulationTime(self):
        return [self.t]


def reply(scene, request):
    func, args = request["func"], request.get("args") or []
    if func == "zmqRemoteApi.require":
        return {"success": True, "ret": []}
    if func == "zmqRemoteApi.info":
        info = {name: {"func": {}} for name in FUNCTIONS}
        info.update({name: {"const": value} for name, value in CONSTANTS.items()})
        return {"success": True, "ret": [info]}
    name = func.removeprefix("sim.")
    if name not in FUNCTIONS:
        return {"success": False, "err": f"unknown function {func}"}
    try:
        return {"success": True, "ret": getattr(scene, name)(*args)}
    except (KeyError, TypeError) as e:
        return {"success": False, "err": str(e)}


def serve(port):
    scene, socket = Scene(), zmq.Context().socket(zmq.REP)
    socket.bind(f"tcp://127.0.0.1:{port}")
    while True:
        request = cbor.loads(socket.recv())
        if scene.t >= scene.die_after:
            return  # gone: the client's next call waits in vain
        socket.send(cbor.dumps(reply(scene, request)))


if __name__ == "__main__":
    serve(int(sys.argv[1]))
