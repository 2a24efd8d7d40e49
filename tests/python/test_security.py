"""Security on the router of config/secure/router.json5, with certificates this test makes:
TLS between every node and the router, user/password logins, and access control. The allowed
cases work (the Rust simulator publishes, the cruise-control identity drives, anyone may watch)
and the refused ones are refused (no credentials, a wrong password, an untrusted router
certificate, plain TCP; vehicle/control from another identity; camera/front from anyone but
the simulator). Loopback only."""

import json
import signal
import subprocess
import threading
import time

import pytest
import zenoh
import zenoh.ext
from conftest import ROOT
from security import client_config, make_ca, make_cert, node_flags

from slipstream_client import decode, encode

USERS = {"sim": "pw-sim", "detect": "pw-detect", "acc": "pw-acc", "operator": "pw-operator"}


def start_router(slipstream_bin, config, endpoint, tmp_path, users):
    """`slipstream router -c config` on `endpoint` with a CA and router certificate made in
    `tmp_path` (ca.pem) and `users` ({user: password}) as its credentials; returns once it
    listens. No shared memory at the router: frames pass it as bytes, as between PCs."""
    make_ca(tmp_path, "ca")
    cert, key = make_cert(tmp_path, "ca", "router", "IP:127.0.0.1,DNS:localhost")
    creds = tmp_path / "credentials.txt"
    creds.write_text("".join(f"{u}:{p}\n" for u, p in users.items()))
    router = subprocess.Popen(
        [slipstream_bin, "router", "-c", config,
         "--cfg", f"listen/endpoints:{json.dumps([endpoint])}",
         "--cfg", f"transport/link/tls/listen_certificate:{json.dumps(str(cert))}",
         "--cfg", f"transport/link/tls/listen_private_key:{json.dumps(str(key))}",
         "--cfg", f"transport/link/tls/root_ca_certificate:{json.dumps(str(tmp_path / 'ca.pem'))}",
         "--cfg", f"transport/auth/usrpwd/dictionary_file:{json.dumps(str(creds))}",
         "--cfg", "transport/shared_memory/enabled:false"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    line = router.stdout.readline()  # "router <zid> listening on ..." once it listens
    if endpoint not in line:
        router.kill()
        raise AssertionError((line, router.communicate(timeout=20)[1]))
    return router


@pytest.fixture
def secure_router(slipstream_bin, free_port, tmp_path):
    endpoint = f"tls/127.0.0.1:{free_port}"
    router = start_router(slipstream_bin, "config/secure/router.json5", endpoint, tmp_path, USERS)
    make_ca(tmp_path, "other-ca")  # a CA the router's certificate does not come from
    try:
        yield {"endpoint": endpoint, "ca": tmp_path / "ca.pem", "other_ca": tmp_path / "other-ca.pem", "dir": tmp_path}
    finally:
        router.terminate()
        router.wait(timeout=20)


def refused(conf):
    """True when a client with this config cannot open a session to the router."""
    try:
        session = zenoh.open(conf)
    except Exception:  # zenoh.ZError: "Unable to connect to any of [...]"
        return True
    session.close()
    return False


def test_clients_without_valid_credentials_or_trust_are_refused(secure_router):
    ep, ca = secure_router["endpoint"], secure_router["ca"]
    assert not refused(client_config(ep, ca, "operator", USERS["operator"])), "the allowed client connects"
    assert refused(client_config(ep, ca)), "no credentials"
    assert refused(client_config(ep, ca, "operator", "wrong")), "wrong password"
    assert refused(client_config(ep, ca, "intruder", "pw-intruder")), "unknown user"
    assert refused(client_config(ep, secure_router["other_ca"], "operator", USERS["operator"])), "untrusted router"
    assert refused(client_config(ep.replace("tls/", "tcp/"), None, "operator", USERS["operator"])), "plain TCP"


def test_only_the_simulator_publishes_camera_and_only_acc_drives(secure_router, sim_bin):
    ep, ca = secure_router["endpoint"], secure_router["ca"]
    sim = subprocess.Popen(
        [sim_bin, "--scenario", "steady-follow", "--duration", "12", "--camera-size", "320x240", "--json",
         *node_flags(ep, ca, "sim", USERS["sim"])],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    lock = threading.Lock()
    seen = {"frames": [], "controls": [], "states": [], "info": []}

    def keep(name, kind):
        def on_sample(sample):
            _, header, body = decode(sample.payload.to_bytes(), expected=kind)
            with lock:
                seen[name].append(body)
        return on_sample

    try:
        watcher = zenoh.open(client_config(ep, ca, "operator", USERS["operator"]))
        acc = zenoh.open(client_config(ep, ca, "acc", USERS["acc"]))
        rogue = zenoh.open(client_config(ep, ca, "detect", USERS["detect"]))
        subs = [
            watcher.declare_subscriber("camera/front", keep("frames", "CameraFrame")),
            watcher.declare_subscriber("vehicle/control", keep("controls", "ControlCommand")),
            watcher.declare_subscriber("vehicle/state", keep("states", "VehicleState")),
            # Latched: the advanced subscriber's history query passes the router's rules too.
            zenoh.ext.declare_advanced_subscriber(watcher, "camera/front/info", keep("info", "CameraInfo"),
                                                  history=zenoh.ext.HistoryConfig(detect_late_publishers=True)),
        ]
        drive = {"throttle": 0.42, "brake": 0.0, "steer": 0.0, "answers_step": None, "perception_stamp_pub_ns": None}
        stop = {"throttle": 0.0, "brake": 1.0, "steer": 0.0, "answers_step": None, "perception_stamp_pub_ns": None}
        fake_frame = {"width": 8, "height": 8, "encoding": "Rgb8", "data": bytes(8 * 8 * 3)}
        # Until each allowed stream has shown up in number or the simulator's 12 s are over
        # (a loaded machine may take seconds to bring it up over TLS); a minute at most.
        deadline = time.monotonic() + 60

        def enough():
            with lock:
                return len(seen["frames"]) > 60 and len(seen["controls"]) > 120 and len(seen["states"]) > 240

        seq = 0
        while time.monotonic() < deadline and sim.poll() is None and (seq < 300 or not enough()):
            stamp = {"seq": seq, "stamp_sim_ns": 0, "stamp_pub_ns": time.time_ns()}
            acc.put("vehicle/control", encode("ControlCommand", stamp, drive), attachment=b"acc")
            rogue.put("vehicle/control", encode("ControlCommand", stamp, stop), attachment=b"rogue")
            rogue.put("camera/front", encode("CameraFrame", stamp, fake_frame), attachment=b"rogue")
            seq += 1
            time.sleep(0.02)
        with lock:
            frames, controls, states, info = (list(seen[k]) for k in ("frames", "controls", "states", "info"))
        for s in subs:
            s.undeclare()
        for session in (watcher, acc, rogue):
            session.close()
        out, err = sim.communicate(timeout=60)
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait(timeout=10)
    assert sim.returncode == 0, err[-2000:]
    # Allowed: the simulator's frames, states and latched camera info reach the watcher.
    assert len(frames) > 50 and all((f["width"], f["height"]) == (320, 240) for f in frames), len(frames)
    assert info and info[0]["width"] == 320, info
    assert len(states) > 200
    # Allowed: the acc identity's commands reach the watcher and the simulator applies them.
    assert len(controls) > 100 and all(c["throttle"] == pytest.approx(0.42) for c in controls), controls[:3]
    applied = [s["applied"] for s in states if s["applied"]["throttle"] > 0]
    assert len(applied) > 100 and all(a["brake"] == 0.0 for a in applied), applied[:3]
    assert all(s["applied"]["brake"] != 1.0 for s in states), "a rogue command was applied"
    report = json.loads(out)
    assert report["control_rejected"] == 0, report


FLEET = ["operator", "car1-sim", "car1-detect", "car1-acc", "car2-sim", "car2-detect", "car2-acc"]


def test_with_the_fleet_acl_a_vehicle_cannot_command_another(slipstream_bin, free_port, tmp_path):
    """config/secure/router-fleet.json5: car1's ACC drives car1 and cannot put on car2's
    control; car2's can; a client without credentials is refused; the router logs the refusal."""
    endpoint, ca = f"tls/127.0.0.1:{free_port}", tmp_path / "ca.pem"
    router = start_router(slipstream_bin, "config/secure/router-fleet.json5", endpoint, tmp_path,
                          {u: f"pw-{u}" for u in FLEET})
    seen, lock = set(), threading.Lock()
    try:
        assert refused(client_config(endpoint, ca)), "no credentials: refused"
        watcher = zenoh.open(client_config(endpoint, ca, "operator", "pw-operator"))
        car1 = zenoh.open(client_config(endpoint, ca, "car1-acc", "pw-car1-acc"))
        car2 = zenoh.open(client_config(endpoint, ca, "car2-acc", "pw-car2-acc"))

        def on_sample(sample):
            with lock:
                seen.add((str(sample.key_expr), sample.payload.to_bytes().decode()))
        sub = watcher.declare_subscriber("*/vehicle/control", on_sample)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            car1.put("car1/vehicle/control", "car1 drives car1")
            car1.put("car2/vehicle/control", "car1 drives car2")
            car2.put("car2/vehicle/control", "car2 drives car2")
            with lock:
                if len(seen) >= 2:
                    break
            time.sleep(0.1)
        time.sleep(0.5)
        sub.undeclare()
        for session in (watcher, car1, car2):
            session.close()
    finally:
        router.send_signal(signal.SIGINT)
        try:
            _, err = router.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            router.kill()
            _, err = router.communicate()
    assert seen == {("car1/vehicle/control", "car1 drives car1"), ("car2/vehicle/control", "car2 drives car2")}, seen
    assert "car1-acc" in err and "unauthorized to Put (ingress) on car2/vehicle/control" in err, err[-2000:]
