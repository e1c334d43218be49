"""`fcu-ground` against the release image under `fcu-pil serve`: parameter files, a recording, the
live view, over TCP and over a serial port.

The command is the binary `FCU_GROUND` names (default `target/release/fcu-ground`, built with
`cargo build --release -p fcu-ground`). `fcu-pil serve` takes one client at a time, so the board is
served here without board.py's pymavlink connection: each run of the command is the client while it
runs. The serial port is a pseudo-terminal whose other end is bridged to the served board's TCP port,
as a USB-UART adapter would be.
"""

import csv
import os
import pty
import select
import signal
import socket
import subprocess
import tempfile
import threading
import time
import tty
import unittest

from board import ELF, PIL, ROOT, free_port, read_params

GROUND = os.environ.get("FCU_GROUND", os.path.join(ROOT, "target", "release", "fcu-ground"))
# The board boots in the emulator before it answers: the first HEARTBEAT may take a while.
BOARD_TIMEOUT_S = "60"


def write_params(path, params):
    with open(path, "w") as f:
        for name, value in params.items():
            f.write(f"{name} {value}\n")


class Served(unittest.TestCase):
    """One served board for every test (a boot each would cost more than the tests)."""

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory(prefix="fcu-ground-")
        cls.port = free_port()
        cls.log = open(os.path.join(cls.dir.name, "serve.log"), "w+")
        cls.proc = subprocess.Popen(
            [PIL, "serve", "--link", f"tcp:127.0.0.1:{cls.port}", "--flash", os.path.join(cls.dir.name, "flash.bin"),
             "--elf", ELF, "--duration", "900"],
            stdout=cls.log, stderr=subprocess.STDOUT)
        deadline = time.time() + 60
        while True:
            if cls.proc.poll() is not None:
                raise RuntimeError(f"fcu-pil serve exited: {cls.serve_output()}")
            try:
                # The listener is up; this probe is the bridge's first client and leaves at once.
                socket.create_connection(("127.0.0.1", cls.port), timeout=1).close()
                break
            except OSError:
                if time.time() > deadline:
                    raise RuntimeError(f"fcu-pil serve did not listen: {cls.serve_output()}")
                time.sleep(0.2)

    @classmethod
    def serve_output(cls):
        cls.log.flush()
        cls.log.seek(0)
        return cls.log.read()

    @classmethod
    def tearDownClass(cls):
        cls.proc.terminate()
        try:
            cls.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            cls.proc.kill()
        cls.log.close()
        cls.dir.cleanup()

    def path(self, name):
        return os.path.join(self.dir.name, name)

    def ground(self, *args, link=None, timeout_s=BOARD_TIMEOUT_S):
        link = link or f"tcp:127.0.0.1:{self.port}"
        cmd = [GROUND, "--link", link, "--timeout", timeout_s, *args]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
        # Kept for the failure messages.
        done.said = f"$ {' '.join(cmd)}\nexit {done.returncode}\nstdout:\n{done.stdout}\nstderr:\n{done.stderr}"
        return done

    def test_pull_edit_push_diff_pull(self):
        pulled = self.path("pulled.param")
        done = self.ground("params", "pull", pulled)
        self.assertEqual(done.returncode, 0, done.said)
        params = read_params(pulled)
        self.assertIn("ANGLE_MAX", params)
        self.assertIn("RCMAP_THROTTLE", params)
        self.assertGreater(len(params), 20)

        # Five degrees more (or less, at the top of its range) of maximum angle.
        new = params["ANGLE_MAX"] + 5 if params["ANGLE_MAX"] <= 40 else params["ANGLE_MAX"] - 5
        edited = self.path("edited.param")
        write_params(edited, {**params, "ANGLE_MAX": new})

        done = self.ground("params", "diff", edited)
        self.assertEqual(done.returncode, 1, done.said)
        self.assertIn("ANGLE_MAX: file", done.stdout, done.said)
        self.assertEqual(sum(1 for l in done.stdout.splitlines() if ": file " in l), 1, done.said)

        done = self.ground("params", "push", edited)
        self.assertEqual(done.returncode, 0, done.said)
        self.assertIn(f"ANGLE_MAX: {params['ANGLE_MAX']:g} -> {new:g}", done.stdout, done.said)
        self.assertIn("1 set, 0 refused", done.stdout, done.said)

        done = self.ground("params", "diff", edited)
        self.assertEqual(done.returncode, 0, done.said)
        self.assertIn("no differences", done.stdout, done.said)

        again = self.path("again.param")
        done = self.ground("params", "pull", again)
        self.assertEqual(done.returncode, 0, done.said)
        self.assertEqual(read_params(again), {**params, "ANGLE_MAX": new})

    def test_a_refused_value_is_named_with_its_rule(self):
        pulled = self.path("before-refusal.param")
        self.assertEqual(self.ground("params", "pull", pulled).returncode, 0)
        before = read_params(pulled)
        wrong = self.path("wrong.param")
        # Far above RATE_RLL_P's maximum; RC1_MIN above its own trim breaks MIN <= TRIM <= MAX.
        write_params(wrong, {"RATE_RLL_P": 1e9, "RC1_MIN": before["RC1_TRIM"] + 10})
        done = self.ground("params", "push", wrong)
        self.assertEqual(done.returncode, 1, done.said)
        self.assertIn("RATE_RLL_P: refused 1000000000 (line 1): above the maximum; the board keeps", done.stdout, done.said)
        self.assertIn("RC1_MIN: refused", done.stdout, done.said)
        self.assertIn("MIN <= TRIM <= MAX", done.stdout, done.said)
        self.assertIn("0 set, 2 refused", done.stdout, done.said)
        # Nothing moved.
        after = self.path("after-refusal.param")
        self.assertEqual(self.ground("params", "pull", after).returncode, 0)
        self.assertEqual(read_params(after), before)

    def test_a_whole_radio_moves_though_its_first_sets_alone_are_refused(self):
        pulled = self.path("radio-before.param")
        self.assertEqual(self.ground("params", "pull", pulled).returncode, 0)
        before = read_params(pulled)
        # Input 1's endpoints 500 us up: the new minimum is above the old trim and the new trim
        # above the old maximum, so in file order the first two sets are refused until the
        # maximum has moved.
        moved = {n: before[n] + 500 for n in ("RC1_MIN", "RC1_TRIM", "RC1_MAX")}
        radio = self.path("radio.param")
        write_params(radio, moved)
        done = self.ground("params", "push", radio)
        self.assertEqual(done.returncode, 0, done.said)
        self.assertIn("3 set, 0 refused", done.stdout, done.said)
        after = self.path("radio-after.param")
        self.assertEqual(self.ground("params", "pull", after).returncode, 0)
        self.assertEqual(read_params(after), {**before, **moved})
        # And back.
        write_params(radio, {n: before[n] for n in moved})
        done = self.ground("params", "push", radio)
        self.assertEqual(done.returncode, 0, done.said)

    def test_a_bad_line_or_an_unknown_name_is_named_and_nothing_is_sent(self):
        bad = self.path("bad.param")
        with open(bad, "w") as f:
            f.write("ANGLE_MAX 25\nRATE_RLL_P\n")
        done = self.ground("params", "push", bad)
        self.assertEqual(done.returncode, 2, done.said)
        self.assertIn("line 2", done.stderr, done.said)
        with open(bad, "w") as f:
            f.write("ANGLE_MAX 21\nNO_SUCH_PARAM 1\n")
        done = self.ground("params", "push", bad)
        self.assertEqual(done.returncode, 2, done.said)
        self.assertIn("line 2: NO_SUCH_PARAM: the board has no such parameter", done.stderr, done.said)
        pulled = self.path("after-bad.param")
        self.assertEqual(self.ground("params", "pull", pulled).returncode, 0)
        self.assertNotEqual(read_params(pulled)["ANGLE_MAX"], 21.0)

    def test_record_writes_the_simulators_csv_and_plot(self):
        out = self.path("record")
        done = self.ground("record", "--out", out, "--duration", "3")
        self.assertEqual(done.returncode, 0, done.said)
        with open(os.path.join(out, "flight.csv")) as f:
            rows = list(csv.DictReader(f))
        self.assertGreater(len(rows), 0, done.said)
        # fcu-sim's columns, in its order.
        with open(os.path.join(out, "flight.csv")) as f:
            header = f.readline().strip()
        self.assertEqual(header, "t_s,state,armed,link,roll_deg,pitch_deg,yaw_deg,est_roll_deg,est_pitch_deg,"
                                 "roll_target_deg,pitch_target_deg,yaw_target_deg,yaw_rate_dps,m1,m2,m3,m4,alt_m,"
                                 "battery_v,thr_us,est_alt_m,alt_target_m,climb_m_s,est_climb_m_s,vmode,alt_mode,"
                                 "baro_fault")
        last = rows[-1]
        self.assertEqual((last["state"], last["armed"]), ("disarmed", "0"))
        # On the bench: level, motors off, the throttle low (the stick's low end, about 1000 us).
        self.assertLess(abs(float(last["est_roll_deg"])), 5.0)
        self.assertEqual([last[m] for m in ("m1", "m2", "m3", "m4")], ["0"] * 4)
        self.assertLess(abs(float(last["thr_us"]) - 1000.0), 150.0)
        # The simulator's truth is not on the link: empty, not made up.
        self.assertEqual((last["roll_deg"], last["alt_m"], last["roll_target_deg"]), ("", "", ""))
        times = [float(r["t_s"]) for r in rows]
        self.assertEqual(times, sorted(times))
        with open(os.path.join(out, "flight.svg")) as f:
            self.assertIn("<svg", f.read(200))

    def test_a_recording_ended_by_ctrl_c_is_written(self):
        out = self.path("record-ctrl-c")
        cmd = [GROUND, "--link", f"tcp:127.0.0.1:{self.port}", "--timeout", BOARD_TIMEOUT_S, "record", "--out", out]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        csv_path = os.path.join(out, ".flight.csv.partial")
        deadline = time.time() + 90
        # Rows are being written: the recording has begun.
        while time.time() < deadline and proc.poll() is None:
            if os.path.exists(csv_path) and os.path.getsize(csv_path) > 2000:
                break
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=30)
        said = f"exit {proc.returncode}\nstdout:\n{stdout}\nstderr:\n{stderr}"
        self.assertEqual(proc.returncode, 0, said)
        with open(os.path.join(out, "flight.csv")) as f:
            self.assertGreater(len(list(csv.DictReader(f))), 0, said)
        self.assertTrue(os.path.exists(os.path.join(out, "flight.svg")), said)

    def test_watch_prints_the_state(self):
        done = self.ground("watch", "--duration", "2")
        self.assertEqual(done.returncode, 0, done.said)
        self.assertIn("state      disarmed  flight state disarmed", done.stdout, done.said)
        self.assertIn("motors     m1 1000", done.stdout, done.said)

    def test_a_serial_port_reaches_the_board(self):
        master, slave = pty.openpty()
        tty.setraw(slave)
        stop = threading.Event()

        def bridge():
            with socket.create_connection(("127.0.0.1", self.port)) as s:
                while not stop.is_set():
                    ready, _, _ = select.select([master, s], [], [], 0.1)
                    if master in ready:
                        try:
                            data = os.read(master, 4096)
                        except OSError:
                            data = b""
                        if data:
                            s.sendall(data)
                    if s in ready:
                        data = s.recv(4096)
                        if not data:
                            return
                        os.write(master, data)

        t = threading.Thread(target=bridge, daemon=True)
        t.start()
        try:
            pulled = self.path("serial.param")
            done = self.ground("params", "pull", pulled, link=f"serial:{os.ttyname(slave)}:115200")
            self.assertEqual(done.returncode, 0, done.said)
            self.assertIn("RCMAP_THROTTLE", read_params(pulled))
        finally:
            stop.set()
            t.join(timeout=5)
            os.close(slave)
            os.close(master)

    def test_a_silent_board_is_named(self):
        with socket.socket() as quiet:
            quiet.bind(("127.0.0.1", 0))
            quiet.listen(1)
            port = quiet.getsockname()[1]
            done = self.ground("params", "pull", self.path("never.param"), link=f"tcp:127.0.0.1:{port}", timeout_s="2")
        self.assertEqual(done.returncode, 2, done.said)
        self.assertIn("the board did not answer", done.stderr, done.said)
        self.assertFalse(os.path.exists(self.path("never.param")))


if __name__ == "__main__":
    unittest.main()
