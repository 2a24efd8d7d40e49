"""Helpers for the security tests: certificates made with the openssl command, Zenoh client
configs, a process started and stopped with its output kept."""

import json
import subprocess

import zenoh


def openssl(*args, cwd):
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def make_ca(d, name):
    """A self-signed CA: d/name.pem, d/name.key."""
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
            "-keyout", f"{name}.key", "-out", f"{name}.pem", "-days", "2", "-subj", f"/CN={name}", cwd=d)
    return d / f"{name}.pem"


def make_cert(d, ca, name, sans):
    """A certificate for `name` signed by CA `ca` (a name given to make_ca)."""
    openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
            "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}", cwd=d)
    (d / f"{name}.ext").write_text(f"subjectAltName={sans}\nbasicConstraints=CA:FALSE\n")
    openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key", "-CAcreateserial",
            "-out", f"{name}.pem", "-days", "2", "-extfile", f"{name}.ext", cwd=d)
    return d / f"{name}.pem", d / f"{name}.key"


def client_config(endpoint, ca=None, user=None, password=None, timeout_ms=4000):
    """A Python client of the router: fails zenoh.open when it cannot connect in time."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("connect/timeout_ms", str(timeout_ms))
    conf.insert_json5("connect/exit_on_failure", "true")
    conf.insert_json5("scouting/multicast/enabled", "false")
    if ca is not None:
        conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(ca)))
    if user is not None:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return conf


def node_flags(endpoint, ca, user, password):
    """Flags for a Rust node using config/secure/node.json5 with these values."""
    return ["-c", "config/secure/node.json5", "-e", endpoint,
            "--cfg", f"transport/link/tls/root_ca_certificate:{json.dumps(str(ca))}",
            "--cfg", f"transport/auth/usrpwd/user:{json.dumps(user)}",
            "--cfg", f"transport/auth/usrpwd/password:{json.dumps(password)}"]
