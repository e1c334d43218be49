"""MAVProxy, headless, against the release image under `fcu-pil serve`: it fetches every
parameter and sets one, and the board keeps the value (read back with pymavlink)."""

import re
import subprocess
import tempfile
import unittest

from board import ServedBoard


class MavProxy(unittest.TestCase):
    def test_mavproxy_fetches_every_parameter_and_sets_one(self):
        with ServedBoard() as board:
            self.assertIsNotNone(board.heartbeat())
            _, count = board.download_params()
            board.conn.close()
            board.conn = None
            # MAVProxy reads its commands from stdin: set one once its download is done.
            script = "sleep 8; echo 'param set ANGLE_MAX 25'; sleep 4; echo 'param show ANGLE_MAX'; sleep 2; echo exit"
            with tempfile.TemporaryDirectory() as logs:
                out = subprocess.run(
                    f"({script}) | mavproxy.py --master tcp:127.0.0.1:{board.port} --state-basedir {logs}",
                    shell=True, capture_output=True, text=True, timeout=60, cwd=logs,
                ).stdout
            self.assertIn(f"Received {count} parameters", out, out)
            self.assertRegex(out, r"ANGLE_MAX\s+25(\.0)?\b", out)
            # The board took it: a new client reads it back.
            from pymavlink import mavutil
            board.conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{board.port}", source_system=255)
            self.assertIsNotNone(board.heartbeat())
            self.assertEqual(board.param_read("ANGLE_MAX").param_value, 25.0)
            self.assertFalse(re.search(r"Unable to find parameter", out), out)
            # The board has no geofence, and MAVProxy must not announce a breach of one.
            self.assertNotIn("fence breach", out)

    def test_mavproxy_mode_command_sets_the_vertical_mode_or_is_refused_by_name(self):
        with ServedBoard() as board:
            self.assertIsNotNone(board.heartbeat())
            has_alt_mode = board.param_read("ALT_MODE") is not None
            board.conn.close()
            board.conn = None
            script = "sleep 8; echo 'mode ALT_HOLD'; sleep 3; echo 'mode STABILIZE'; sleep 3; echo exit"
            with tempfile.TemporaryDirectory() as logs:
                out = subprocess.run(
                    f"({script}) | mavproxy.py --master tcp:127.0.0.1:{board.port} --state-basedir {logs}",
                    shell=True, capture_output=True, text=True, timeout=60, cwd=logs,
                ).stdout
            if has_alt_mode:
                self.assertEqual(out.count("Got COMMAND_ACK: DO_SET_MODE: ACCEPTED"), 2, out)
            else:
                self.assertEqual(out.count("Got COMMAND_ACK: DO_SET_MODE: DENIED"), 2, out)
                self.assertIn("Mode refused: no altitude hold on this board", out)
            self.assertNotIn("Unknown mode", out)


if __name__ == "__main__":
    unittest.main()
