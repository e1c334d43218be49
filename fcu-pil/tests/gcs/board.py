"""The emulated board under `fcu-pil serve`, for ground-station tests written with pymavlink.

Each `ServedBoard` starts its own `fcu-pil serve` on a free local port (the release image, a
flash file of its own), waits until it listens, and connects pymavlink to it as a ground station
would connect through a USB-UART adapter.
"""

import os
import socket
import subprocess
import tempfile
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set before the import)

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
PIL = os.path.join(ROOT, "target", "release", "fcu-pil")
ELF = os.environ.get(
    "FCU_PIL_ELF", os.path.join(ROOT, "fcu-firmware", "target", "thumbv7em-none-eabihf", "release", "fcu-firmware")
)
MAV = mavutil.mavlink


def read_params(path):
    """{NAME: value} of a parameter file (MAVProxy's `param save` format), in the file's order."""
    out = {}
    with open(path) as f:
        for line in f:
            words = line.split("#")[0].split()
            if words:
                out[words[0]] = float(words[1])
    return out


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServedBoard:
    """`fcu-pil serve` and a pymavlink connection to it (system 255, a ground station)."""

    def __init__(self, scenario=None, power_cut=None, flash=None, params=None, params_text=None, duration_s=600):
        """`params` names a parameter file to boot with; `params_text` is one's text."""
        self.port = free_port()
        self._dir = tempfile.TemporaryDirectory(prefix="fcu-gcs-")
        if params_text is not None:
            params = os.path.join(self._dir.name, "tune.parm")
            with open(params, "w") as f:
                f.write(params_text)
        self.flash = flash or os.path.join(self._dir.name, "flash.bin")
        cmd = [PIL, "serve", "--link", f"tcp:127.0.0.1:{self.port}", "--flash", self.flash, "--elf", ELF,
               "--duration", str(duration_s)]
        if scenario:
            cmd += ["--scenario", scenario]
        if power_cut:
            cmd += ["--power-cut", power_cut]
        if params:
            cmd += ["--params", params]
        self.log = open(os.path.join(self._dir.name, "serve.log"), "w+")
        self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT)
        self.conn = None
        self.seen_texts = []
        deadline = time.time() + 60
        while time.time() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"fcu-pil serve exited: {self.serve_output()}")
            try:
                self.conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{self.port}", source_system=255,
                                                       source_component=190, autoreconnect=False)
                break
            except OSError:
                time.sleep(0.2)
        if self.conn is None:
            raise RuntimeError(f"fcu-pil serve did not listen: {self.serve_output()}")

    def serve_output(self):
        self.log.flush()
        self.log.seek(0)
        return self.log.read()

    def close(self):
        if self.conn is not None:
            self.conn.close()
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()
        self._dir.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def recv(self, kind, timeout=5.0, cond=None):
        """The next message of `kind` (and matching `cond`), or None after `timeout` s."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            msg = self.conn.recv_match(blocking=True, timeout=max(0.05, deadline - time.time()))
            if msg is None:
                continue
            if msg.get_type() == "STATUSTEXT" and kind != "STATUSTEXT":
                # Kept for `texts`: a STATUSTEXT may come while another message is awaited.
                self.seen_texts.append(msg.text)
            if msg.get_type() == kind and (cond is None or cond(msg)):
                return msg
        return None

    def heartbeat(self, timeout=30.0):
        return self.recv("HEARTBEAT", timeout, lambda m: m.get_srcSystem() == 1)

    def texts(self, timeout=2.0):
        """Every STATUSTEXT received since the last call, and within `timeout` s more."""
        out, self.seen_texts = self.seen_texts, []
        deadline = time.time() + timeout
        while time.time() < deadline:
            m = self.recv("STATUSTEXT", deadline - time.time())
            if m is not None:
                out.append(m.text)
        return out

    def param_set(self, name, value):
        self.conn.mav.param_set_send(1, 1, name.encode(), value, MAV.MAV_PARAM_TYPE_REAL32)
        return self.recv("PARAM_VALUE", 5.0, lambda m: m.param_id == name)

    def param_read(self, name=None, index=-1):
        ident = name.encode() if name else b""
        self.conn.mav.param_request_read_send(1, 1, ident, index)
        if name:
            return self.recv("PARAM_VALUE", 5.0, lambda m: m.param_id == name)
        return self.recv("PARAM_VALUE", 5.0, lambda m: m.param_index == index)

    def command(self, command, *params, timeout=5.0):
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(1, 1, command, 0, *p)
        return self.recv("COMMAND_ACK", timeout, lambda m: m.command == command)

    def download_params(self, drop_index=None, timeout=30.0):
        """PARAM_REQUEST_LIST: {index: (name, value)}, and the count the board announced."""
        self.conn.mav.param_request_list_send(1, 1)
        got, count = {}, None
        deadline = time.time() + timeout
        while time.time() < deadline and (count is None or len(got) < count - (drop_index is not None)):
            m = self.recv("PARAM_VALUE", 2.0)
            if m is None:
                break
            count = m.param_count
            if m.param_index == drop_index:
                continue
            got[m.param_index] = (m.param_id, m.param_value)
        return got, count
