"""pymavlink against the release image under `fcu-pil serve`: what a ground station relies on.

Run by `scripts/gcs-tests` (CI), which builds fcu-pil and the firmware first.
"""

import os
import tempfile
import time
import unittest

from board import MAV, ServedBoard


class OnTheBench(unittest.TestCase):
    """The board on the bench, disarmed (sticks centred, throttle low)."""

    @classmethod
    def setUpClass(cls):
        cls.board = ServedBoard()
        cls.hb = cls.board.heartbeat()
        if cls.hb is None:
            out = cls.board.serve_output()
            cls.board.close()
            raise AssertionError(f"no HEARTBEAT from system 1 within 30 s; serve said:\n{out}")

    @classmethod
    def tearDownClass(cls):
        cls.board.close()

    def test_heartbeat_names_a_generic_quadrotor_disarmed_in_mavlink_2(self):
        hb = self.board.heartbeat()
        self.assertEqual((hb.get_srcSystem(), hb.get_srcComponent()), (1, 1))
        self.assertEqual(hb.type, MAV.MAV_TYPE_QUADROTOR)
        self.assertEqual(hb.autopilot, MAV.MAV_AUTOPILOT_GENERIC)
        self.assertEqual(hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED, 0)
        self.assertIn(hb.system_status, (MAV.MAV_STATE_BOOT, MAV.MAV_STATE_STANDBY))
        self.assertEqual(hb.get_header().mlen if hasattr(hb.get_header(), "mlen") else 9, 9)
        self.assertTrue(self.board.conn.WIRE_PROTOCOL_VERSION == "2.0" or self.board.conn.mavlink20())

    def test_telemetry_streams_at_their_rates(self):
        counts = {}
        start = time.time()
        while time.time() - start < 2.0:
            m = self.board.conn.recv_match(blocking=True, timeout=0.5)
            if m is not None:
                counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
        for kind, at_least in [("ATTITUDE", 25), ("RC_CHANNELS", 10), ("SERVO_OUTPUT_RAW", 10), ("SYS_STATUS", 1),
                               ("BATTERY_STATUS", 1), ("HEARTBEAT", 1)]:
            self.assertGreaterEqual(counts.get(kind, 0), at_least, f"{kind} in 2 s: {counts}")

    def test_a_full_download_survives_a_lost_value_fetched_again_by_index(self):
        got, count = self.board.download_params(drop_index=7)
        self.assertIsNotNone(count)
        self.assertGreater(count, 20)
        self.assertNotIn(7, got)
        self.assertEqual(len(got), count - 1)
        again = self.board.param_read(index=7)
        self.assertIsNotNone(again, "PARAM_REQUEST_READ by index 7 got no answer")
        self.assertEqual(again.param_index, 7)
        names = [n for n, _ in got.values()] + [again.param_id]
        self.assertEqual(len(set(names)), count, "names repeat")
        for n in names:
            self.assertTrue(len(n) <= 16 and n == n.upper(), n)
        by_name = self.board.param_read(name=again.param_id)
        self.assertEqual((by_name.param_index, by_name.param_value), (7, again.param_value))

    def test_a_set_is_echoed_with_the_value_in_force(self):
        echo = self.board.param_set("ANG_RLL_P", 5.5)
        self.assertIsNotNone(echo)
        self.assertAlmostEqual(echo.param_value, 5.5, places=5)
        self.assertAlmostEqual(self.board.param_read("ANG_RLL_P").param_value, 5.5, places=5)
        self.board.param_set("ANG_RLL_P", 6.5)

    def test_out_of_range_and_nan_are_refused_with_the_old_value(self):
        old = self.board.param_read("ANG_PIT_P").param_value
        for bad in (1e6, -3.0, float("nan")):
            echo = self.board.param_set("ANG_PIT_P", bad)
            self.assertIsNotNone(echo, f"no echo for {bad}")
            self.assertEqual(echo.param_value, old, f"{bad} was taken")
        self.assertEqual(self.board.param_read("ANG_PIT_P").param_value, old)

    def test_an_unknown_name_is_refused_with_a_statustext(self):
        self.board.conn.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, MAV.MAV_PARAM_TYPE_REAL32)
        texts = self.board.texts(2.0)
        self.assertTrue(any("NO_SUCH_PARAM" in t for t in texts), texts)

    def test_an_unknown_command_is_unsupported(self):
        ack = self.board.command(MAV.MAV_CMD_DO_SET_ROI_LOCATION, 1, 2, 3)
        self.assertIsNotNone(ack)
        self.assertEqual(ack.result, MAV.MAV_RESULT_UNSUPPORTED)

    def test_arming_from_the_link_is_refused(self):
        ack = self.board.command(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        self.assertIsNotNone(ack)
        self.assertNotEqual(ack.result, MAV.MAV_RESULT_ACCEPTED)
        hb = self.board.heartbeat()
        self.assertEqual(hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED, 0)

    def test_a_mission_list_is_empty_and_the_version_carries_mavlink2(self):
        self.board.conn.mav.mission_request_list_send(1, 1)
        count = self.board.recv("MISSION_COUNT", 5.0)
        self.assertIsNotNone(count)
        self.assertEqual(count.count, 0)
        ack = self.board.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        self.assertEqual(ack.result, MAV.MAV_RESULT_ACCEPTED)
        version = self.board.recv("AUTOPILOT_VERSION", 5.0)
        self.assertIsNotNone(version)
        self.assertTrue(version.capabilities & MAV.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
        self.assertTrue(version.capabilities & MAV.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)


class SaveAndReboot(unittest.TestCase):
    def test_saved_values_come_back_after_a_reboot(self):
        with ServedBoard() as board:
            self.assertIsNotNone(board.heartbeat())
            self.assertAlmostEqual(board.param_set("RATE_RLL_P", 180.0).param_value, 180.0)
            self.assertAlmostEqual(board.param_set("RC1_TRIM", 1500.0).param_value, 1500.0)
            ack = board.command(MAV.MAV_CMD_PREFLIGHT_STORAGE, 1, timeout=5.0)
            self.assertEqual(ack.result, MAV.MAV_RESULT_ACCEPTED)
            texts = board.texts(3.0)
            self.assertTrue(any("saved" in t for t in texts), texts)
            ack = board.command(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
            self.assertEqual(ack.result, MAV.MAV_RESULT_ACCEPTED)
            # The board goes quiet, boots again and says where its parameters came from.
            texts = board.texts(8.0)
            self.assertTrue(any("loaded from flash" in t for t in texts), texts)
            self.assertAlmostEqual(board.param_read("RATE_RLL_P").param_value, 180.0)
            self.assertAlmostEqual(board.param_read("RC1_TRIM").param_value, 1500.0)


class ParamsFile(unittest.TestCase):
    def test_serve_boots_with_a_parameter_file_as_the_saved_set(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "tune.parm")
            with open(path, "w") as f:
                f.write("# from MAVProxy's param save\nRATE_RLL_P 190\nRC2_REV -1\n")
            with ServedBoard(params=path) as board:
                self.assertIsNotNone(board.heartbeat())
                self.assertEqual(board.param_read("RATE_RLL_P").param_value, 190.0)
                self.assertEqual(board.param_read("RC2_REV").param_value, -1.0)
                # The boot's own STATUSTEXT went out before the client connected: a reboot says
                # where the set came from.
                board.texts(0.1)
                self.assertEqual(board.command(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1).result, MAV.MAV_RESULT_ACCEPTED)
                texts = board.texts(8.0)
                self.assertTrue(any("loaded from flash" in t for t in texts), texts)


class Armed(unittest.TestCase):
    """The hover scenario's pilot arms by gesture and takes off (on the bench)."""

    def test_radio_parameters_are_refused_while_armed_and_gains_are_taken(self):
        with ServedBoard(scenario="hover") as board:
            armed = board.recv("HEARTBEAT", 30.0, lambda m: m.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED)
            self.assertIsNotNone(armed, "the scenario's pilot did not arm within 30 s")
            old = board.param_read("RC1_MIN").param_value
            echo = board.param_set("RC1_MIN", old + 10.0)
            self.assertEqual(echo.param_value, old)
            gain = board.param_set("ANG_RLL_P", 6.0)
            self.assertAlmostEqual(gain.param_value, 6.0, places=5)
            ack = board.command(MAV.MAV_CMD_PREFLIGHT_STORAGE, 1)
            self.assertNotEqual(ack.result, MAV.MAV_RESULT_ACCEPTED)


class Noise(unittest.TestCase):
    def test_random_bytes_in_flight_change_nothing_and_the_link_works_after(self):
        """Five seconds of random bytes at the line's full rate into USART1 while the hover
        scenario's pilot flies: the board stays armed, its attitude stream keeps its rate,
        no parameter moves, and the link answers afterwards."""
        import random
        with ServedBoard(scenario="hover") as board:
            armed = board.recv("HEARTBEAT", 30.0, lambda m: m.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED)
            self.assertIsNotNone(armed, "the scenario's pilot did not arm within 30 s")
            before, count = board.download_params()
            self.assertEqual(len(before), count)
            rng = random.Random(7)
            sock = board.conn.port
            attitudes, end = 0, time.time() + 5.0
            while time.time() < end:
                # 1152 bytes every 0.1 s: 115200 baud.
                sock.send(bytes(rng.randrange(256) for _ in range(1152)))
                stop = time.time() + 0.1
                while time.time() < stop:
                    m = board.conn.recv_match(blocking=True, timeout=0.02)
                    if m is not None and m.get_type() == "ATTITUDE":
                        attitudes += 1
            self.assertGreaterEqual(attitudes, 5 * 20, "the attitude stream fell below 20 Hz under noise")
            hb = board.heartbeat(5.0)
            self.assertTrue(hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED, "the noise disarmed the board")
            # The line is back to the ground station once the last noise has been clocked in.
            answered = None
            deadline = time.time() + 15.0
            while answered is None and time.time() < deadline:
                answered = board.param_read("ANGLE_MAX")
            self.assertIsNotNone(answered, "no answer within 15 s of the noise")
            after, count_after = board.download_params()
            self.assertEqual((count_after, after), (count, before), "a parameter moved")
            self.assertAlmostEqual(board.param_set("ANG_YAW_P", 2.5).param_value, 2.5, places=5)


class PowerCut(unittest.TestCase):
    """A power cut at every eighth of a save's erase, and in the first, a middle and the last
    (commit) word of its programming, leaves a valid set: the old values or the new, never a
    mix."""

    def cut(self, where, flash=None):
        with ServedBoard(power_cut=where, flash=flash) as board:
            self.assertIsNotNone(board.heartbeat(), where)
            old = (board.param_read("RATE_PIT_P").param_value, board.param_read("RATE_PIT_I").param_value)
            new = (old[0] + 1.0, old[1] + 1.0)
            board.param_set("RATE_PIT_P", new[0])
            board.param_set("RATE_PIT_I", new[1])
            board.texts(0.1)
            board.command(MAV.MAV_CMD_PREFLIGHT_STORAGE, 1)
            # The cut powers the board off and on (no reboot was asked for): it boots again and
            # says what it found in flash.
            texts = board.texts(10.0)
            booted = [t for t in texts if "loaded from flash" in t or "no saved parameters" in t or "refused" in t]
            self.assertTrue(booted, f"{where}: no boot after the cut: {texts}")
            now = (board.param_read("RATE_PIT_P").param_value, board.param_read("RATE_PIT_I").param_value)
            self.assertIn(now, [old, new], f"{where}: a mixed set")
            return now == new

    def test_cuts_while_programming_a_snapshot(self):
        # Blank flash: the first save programs the snapshot's words without an erase.
        for word in (1, 20, "last"):
            for k in (1, 4, 7):
                with self.subTest(word=word, k=k):
                    n = word if word != "last" else record_words()
                    self.cut(f"program:{k}/8@{n}")

    def test_cuts_while_erasing_a_sector(self):
        # Both sectors hold no valid snapshot and are not erased: the save erases one first.
        for k in range(1, 8):
            with self.subTest(k=k):
                with tempfile.TemporaryDirectory() as d:
                    flash = os.path.join(d, "flash.bin")
                    image = bytearray(b"\xff" * 256 * 1024)
                    image[0x4000:0xC000] = bytes(0x8000)
                    with open(flash, "wb") as f:
                        f.write(image)
                    self.cut(f"erase:{k}/8", flash=flash)


def record_words():
    """Words in one snapshot: the parameter count plus six (magic, sequence, layout hash,
    length, CRC, commit), as fcu-core's snapshot format has it."""
    with ServedBoard() as board:
        board.heartbeat()
        _, count = board.download_params()
    return count + 6


if __name__ == "__main__":
    unittest.main()
