"""A transmitter that is not the reference's Devo 7E, set up over the link and flown on the image.

The ground station sets the radio parameters of `fcu-testkit/data/other-transmitter.parm` one
PARAM_SET at a time, as QGroundControl or MAVProxy's `param load` would, and saves them. The
board's flash, as the emulator keeps it, is then flown by `fcu-pil fly --flash` through the
`other-transmitter` scenario (its channels in another order, pitch reversed, 1000..2000 us):
it arms by gesture and hovers. The same flight from a flash where nothing was saved does not
arm. No recompile: the same release image throughout.
"""

import os
import subprocess
import tempfile
import unittest

from board import ELF, MAV, PIL, ROOT, ServedBoard, read_params

PARM = os.path.join(ROOT, "fcu-testkit", "data", "other-transmitter.parm")


def fly(flash, out_dir):
    cmd = [PIL, "fly", "--scenario", "other-transmitter", "--elf", ELF, "--flash", flash, "--out", out_dir]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=900)


class AnotherTransmitter(unittest.TestCase):
    def test_set_up_over_the_link_it_arms_by_gesture_and_hovers_on_the_image(self):
        with tempfile.TemporaryDirectory(prefix="fcu-tx-") as d:
            untouched = os.path.join(d, "untouched.bin")
            flash = os.path.join(d, "flash.bin")
            with ServedBoard(flash=untouched, duration_s=20) as b:
                self.assertIsNotNone(b.heartbeat(), b.serve_output())
            with ServedBoard(flash=flash) as b:
                self.assertIsNotNone(b.heartbeat(), b.serve_output())
                for name, value in read_params(PARM).items():
                    echo = b.param_set(name, value)
                    self.assertIsNotNone(echo, f"no echo for {name}")
                    self.assertEqual(echo.param_value, value, f"{name} refused: {b.texts(0.5)}")
                # Every value as the file has it, read back (a map set moves another).
                for name, value in read_params(PARM).items():
                    self.assertEqual(b.param_read(name).param_value, value, name)
                ack = b.command(MAV.MAV_CMD_PREFLIGHT_STORAGE, 1)
                self.assertIsNotNone(ack)
                self.assertEqual(ack.result, MAV.MAV_RESULT_ACCEPTED)
                texts = b.texts(timeout=6.0)
                self.assertIn("parameters saved", texts, b.serve_output())

            run = fly(flash, os.path.join(d, "set-up"))
            self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
            self.assertIn("[pass] armed by gesture", run.stdout)
            self.assertIn("[pass] altitude", run.stdout)

            run = fly(untouched, os.path.join(d, "as-shipped"))
            self.assertEqual(run.returncode, 1, run.stdout + run.stderr)
            self.assertIn("[FAIL] armed by gesture", run.stdout)


if __name__ == "__main__":
    unittest.main()
