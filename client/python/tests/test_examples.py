"""The examples as a first-time user runs them: examples/stream_corridor.py and stream_folder.py.

Each example runs as its own process with this interpreter (PYTHONPATH has the built package),
against a real recogd on a free port or against a port where nothing listens. Checked: the usage
without arguments (exit 2) and with --help (exit 0); on tests/data/corridor, with the settings
client/python/README.md gives, the loop lines and the summary line, and that the README shows that
very command and output; without the settings, the summary and the hint why there is no loop;
stream_folder's loop and summary lines; and one line on stderr, exit 1 and no traceback for a
folder that does not exist, a folder without images, a map that exists, a frame that is not an
image (stream_corridor names it and goes on: exit 0) and a server that is not there (naming its
address and `bash scripts/run.sh`); bad settings are a usage error (exit 2). stream_folder's
--bag: bags of tests/data/corridor written by tests/testing/write_bag.py (JPEG bytes; mono8
pixels recorded last frame first) give the folder's loops, their stamps are the frames' times,
and a topic that is not there (the bag's topics listed), an unsupported encoding, a file that is
not a bag and rosbag missing are each one line (skipped without Python's rosbag).

Environment (ctest sets it): RECOGD, RECOG_SOURCE_DIR, PYTHONPATH. Exits with 77 (skipped) when
Python's grpc or protobuf modules are missing.
"""

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

try:
    from recogd_process import Recogd, free_port
    from recog_client import RecognitionClient
except ModuleNotFoundError as missing:
    if missing.name.split(".")[0] not in ("grpc", "google"):
        raise  # the package is not on PYTHONPATH: an error, not a skip
    print(f"SKIP: {missing} (Debian: apt-get install python3-grpcio python3-protobuf)",
          file=sys.stderr)
    sys.exit(77)

SOURCE = Path(os.environ.get("RECOG_SOURCE_DIR", Path(__file__).resolve().parents[3]))
EXAMPLES = SOURCE / "client" / "python" / "examples"
CORRIDOR_EXAMPLE = EXAMPLES / "stream_corridor.py"
FOLDER_EXAMPLE = EXAMPLES / "stream_folder.py"
README = SOURCE / "client" / "python" / "README.md"
CORRIDOR = SOURCE / "tests" / "data" / "corridor"
#: The settings that make the fixture's 4 frames give loops, as the README gives them.
SETTINGS = ["temporal_matches=0", "recent_frames=1"]
#: Bags: written by this interpreter (it needs Debian's python3-rosbag), frames 1 s apart.
WRITE_BAG = SOURCE / "tests" / "testing" / "write_bag.py"
HAVE_ROSBAG = importlib.util.find_spec("rosbag") is not None
TOPIC = "/camera/image_raw"
#: SETTINGS for frames with timestamps 1 s apart: tau_c leaves out the frame before, as
#: recent_frames=1 does for frames without.
BAG_SETTINGS = {"temporal_matches": 0, "recent_frames": 1, "recent_seconds": 1.5}
#: The command the README documents, from the repository's root.
README_COMMAND = ("client/python/examples/stream_corridor.py tests/data/corridor "
                  "temporal_matches=0 recent_frames=1")


def run(example: Path, *args: str, server: str = "",
        pythonpath: str = "") -> subprocess.CompletedProcess:
    """Runs ``example`` with ``args`` from the repository's root, RECOG_SERVER = ``server``, with
    ``pythonpath`` before PYTHONPATH."""
    environment = {**os.environ, "RECOG_SERVER": server}
    if pythonpath:
        environment["PYTHONPATH"] = os.pathsep.join(
            filter(None, [pythonpath, environment.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, str(example), *map(str, args)], cwd=SOURCE,
                          env=environment, capture_output=True, text=True, timeout=120,
                          check=False)


def write_bag(path: Path, *args: str) -> Path:
    """Writes a bag of tests/data/corridor's frames, 1 s apart, with write_bag.py's ``args``."""
    subprocess.run([sys.executable, str(WRITE_BAG), str(path), "--images", str(CORRIDOR),
                    "--topic", TOPIC, "--period", "1", *args], check=True, capture_output=True,
                   timeout=120)
    return path


def without_names(lines: list[str]) -> list[str]:
    """stream_folder's loop lines without the frames' names (file names, or a bag's stamps)."""
    return [re.sub(r" \([^)]*\)", "", line) for line in lines]


class ExamplesTest(unittest.TestCase):
    """One recogd for the class; each test streams into maps of its own."""

    @classmethod
    def setUpClass(cls):
        """Starts recogd and waits until it serves."""
        cls.server = Recogd()
        cls.server.wait_until_serving()

    @classmethod
    def tearDownClass(cls):
        """Stops recogd and checks that it exits with 0."""
        cls.server.stop()

    def assert_one_line_error(self, run_: subprocess.CompletedProcess, example: Path,
                              *fragments: str):
        """Checks exit status 1, nothing on stdout, and one line on stderr: the example's name,
        then ``fragments``."""
        self.assertEqual(run_.returncode, 1, run_.stdout + run_.stderr)
        self.assertEqual(run_.stdout, "")
        self.assertNotIn("Traceback", run_.stderr)
        lines = run_.stderr.splitlines()
        self.assertEqual(len(lines), 1, run_.stderr)
        self.assertTrue(lines[0].startswith(f"{example.stem}: "), lines[0])
        for fragment in fragments:
            self.assertIn(fragment, lines[0])

    def test_without_arguments_each_example_prints_its_usage_and_exits_2(self):
        for example in (CORRIDOR_EXAMPLE, FOLDER_EXAMPLE):
            with self.subTest(example.name):
                answer = run(example)
                self.assertEqual(answer.returncode, 2, answer.stderr)
                self.assertEqual(answer.stdout, "")
                self.assertTrue(answer.stderr.startswith(f"usage: {example.name} "),
                                answer.stderr)
                self.assertIn("error: the following arguments are required:", answer.stderr)
                self.assertNotIn("Traceback", answer.stderr)

    def test_help_prints_the_usage_and_exits_0(self):
        for example, argument in ((CORRIDOR_EXAMPLE, "KEY=VALUE"), (FOLDER_EXAMPLE, "--map")):
            for flag in ("-h", "--help"):
                with self.subTest(example=example.name, flag=flag):
                    answer = run(example, flag)
                    self.assertEqual(answer.returncode, 0, answer.stderr)
                    self.assertTrue(answer.stdout.startswith(f"usage: {example.name} "))
                    self.assertIn(argument, answer.stdout)

    def test_the_corridor_with_the_readme_settings_prints_its_loops_and_a_summary(self):
        answer = run(CORRIDOR_EXAMPLE, CORRIDOR, *SETTINGS, server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        self.assertEqual(answer.stderr, "")
        self.assertEqual(answer.stdout.splitlines(),
                         ["41.jpg revisits 1.jpg", "60.jpg revisits 20.jpg", "4 frames, 2 loops"])
        # The README gives this command and shows this output, verbatim.
        readme = README.read_text(encoding="utf-8")
        self.assertIn(README_COMMAND + "\n" + answer.stdout, readme)

    def test_without_settings_the_corridor_says_why_it_found_no_loop(self):
        answer = run(CORRIDOR_EXAMPLE, "--map", "defaults", CORRIDOR, server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        self.assertEqual(answer.stdout, "4 frames, 0 loops\n")
        self.assertIn("recent_frames=20", answer.stderr)
        self.assertIn("try temporal_matches=0 recent_frames=1", answer.stderr)

    def test_the_options_may_follow_the_settings_and_options_name_the_server_and_map(self):
        answer = run(CORRIDOR_EXAMPLE, CORRIDOR, *SETTINGS, "--map", "after",
                     "--server", self.server.target)  # RECOG_SERVER is empty
        self.assertEqual(answer.returncode, 0, answer.stderr)
        self.assertEqual(answer.stdout.splitlines()[-1], "4 frames, 2 loops")
        with RecognitionClient(self.server.target) as client:
            info = client.get_map("after")
        self.assertEqual((info.frames, info.settings.temporal_matches,
                          info.settings.recent_frames), (4, 0, 1))

    def test_a_map_that_exists_is_refused_and_left_as_it_is(self):
        first = run(CORRIDOR_EXAMPLE, "--map", "twice", CORRIDOR, *SETTINGS,
                    server=self.server.target)
        self.assertEqual(first.returncode, 0, first.stderr)
        again = run(CORRIDOR_EXAMPLE, "--map", "twice", CORRIDOR, *SETTINGS,
                    server=self.server.target)
        self.assert_one_line_error(again, CORRIDOR_EXAMPLE, "map 'twice' already exists on "
                                   f"{self.server.target}", "recog maps delete twice")
        with RecognitionClient(self.server.target) as client:
            self.assertEqual(client.get_map("twice").frames, 4)

    def test_a_frame_that_is_not_an_image_is_named_and_the_others_go_on(self):
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as folder:
            for name in ("1.jpg", "20.jpg", "41.jpg", "60.jpg"):
                shutil.copy(CORRIDOR / name, folder)
            Path(folder, "30.jpg").write_text("not a JPEG", encoding="utf-8")
            answer = run(CORRIDOR_EXAMPLE, "--map", "broken", folder, *SETTINGS,
                         server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        self.assertTrue(answer.stderr.startswith("30.jpg: not added: "), answer.stderr)
        self.assertEqual(answer.stdout.splitlines(),
                         ["41.jpg revisits 1.jpg", "60.jpg revisits 20.jpg",
                          "5 frames, 2 loops (1 not added)"])

    def test_stream_folder_prints_each_loop_and_a_summary(self):
        with RecognitionClient(self.server.target) as client:
            client.create_map("lab", {"temporal_matches": 0, "recent_frames": 1})
        answer = run(FOLDER_EXAMPLE, "--map", "lab", CORRIDOR, server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        lines = answer.stdout.splitlines()
        self.assertEqual(len(lines), 3, answer.stdout)
        self.assertRegex(lines[0], r"^frame 2 \(41\.jpg\) closes a loop with frame 0 "
                         r"\(1\.jpg\): \d+ inliers, spread \d\.\d\d, confirmations 0$")
        self.assertRegex(lines[1], r"^frame 3 \(60\.jpg\) closes a loop with frame 1 "
                         r"\(20\.jpg\): ")
        self.assertEqual(lines[2], "4 frames streamed into map 'lab', 2 loops")

    @unittest.skipUnless(HAVE_ROSBAG, "no Python rosbag (Debian: python3-rosbag)")
    def test_stream_folder_streams_a_bag_with_the_loops_of_its_folder(self):
        with RecognitionClient(self.server.target) as client:
            for name in ("bag-folder", "bag-jpeg", "bag-mono8"):
                client.create_map(name, BAG_SETTINGS)
        folder = run(FOLDER_EXAMPLE, "--map", "bag-folder", CORRIDOR, server=self.server.target)
        self.assertEqual(folder.returncode, 0, folder.stderr)
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as temporary:
            for encoding, extra in (("jpeg", []), ("mono8", ["--reverse", "--compression", "lz4"])):
                with self.subTest(encoding):
                    bag = write_bag(Path(temporary, f"{encoding}.bag"), "--encoding", encoding,
                                    *extra)
                    answer = run(FOLDER_EXAMPLE, "--map", f"bag-{encoding}", "--bag", bag,
                                 "--topic", TOPIC, server=self.server.target)
                    self.assertEqual(answer.returncode, 0, answer.stderr)
                    self.assertEqual(answer.stderr, "")
                    lines = answer.stdout.splitlines()
                    self.assertRegex(lines[0], r"^frame 2 \(stamp 1002\.000\) closes a loop with "
                                     r"frame 0 \(stamp 1000\.000\): ")
                    self.assertEqual(without_names(lines[:-1]),
                                     without_names(folder.stdout.splitlines()[:-1]))
                    self.assertEqual(len(lines), 3, answer.stdout)
                    self.assertEqual(lines[-1], f"4 frames streamed into map 'bag-{encoding}', "
                                     "2 loops")

    @unittest.skipUnless(HAVE_ROSBAG, "no Python rosbag (Debian: python3-rosbag)")
    def test_a_bags_stamps_are_its_frames_times(self):
        # tau_c of 100 s leaves out every frame of a bag 3 s long, but not of the folder (no
        # timestamps: recent_frames=1).
        settings = {**BAG_SETTINGS, "recent_seconds": 100}
        with RecognitionClient(self.server.target) as client:
            client.create_map("stamps-folder", settings)
            client.create_map("stamps-bag", settings)
        folder = run(FOLDER_EXAMPLE, "--map", "stamps-folder", CORRIDOR, server=self.server.target)
        self.assertEqual(folder.stdout.splitlines()[-1],
                         "4 frames streamed into map 'stamps-folder', 2 loops")
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as temporary:
            bag = write_bag(Path(temporary, "corridor.bag"), "--encoding", "jpeg")
            answer = run(FOLDER_EXAMPLE, "--map", "stamps-bag", "--bag", bag, "--topic", TOPIC,
                         server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        self.assertEqual(answer.stdout, "4 frames streamed into map 'stamps-bag', 0 loops\n")

    @unittest.skipUnless(HAVE_ROSBAG, "no Python rosbag (Debian: python3-rosbag)")
    def test_a_bag_that_cannot_be_streamed_is_one_line(self):
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as temporary:
            bag = write_bag(Path(temporary, "corridor.bag"), "--encoding", "jpeg")
            yuv = write_bag(Path(temporary, "yuv.bag"), "--encoding", "yuv422")
            not_a_bag = Path(temporary, "notes.bag")
            not_a_bag.write_text("not a bag", encoding="utf-8")
            hidden = Path(temporary, "hidden")
            hidden.mkdir()
            Path(hidden, "rosbag.py").write_text(
                "raise ModuleNotFoundError(\"No module named 'rosbag'\", name='rosbag')\n",
                encoding="utf-8")
            topics = f"its topics: {TOPIC} (sensor_msgs/CompressedImage, 4 messages)"
            for args, fragments, pythonpath in (
                    (["--bag", bag, "--topic", "/cam"], [f"{bag}: no image topic /cam; {topics}"],
                     ""),
                    (["--bag", bag], [f"{bag}: give --topic; {topics}"], ""),
                    (["--bag", yuv, "--topic", TOPIC],
                     [f"{yuv}: encoding 'yuv422' of the image at stamp 1000.000 is not mono8, "
                      "rgb8 or bgr8"], ""),
                    (["--bag", not_a_bag, "--topic", TOPIC], [f"{not_a_bag}: "], ""),
                    (["--bag", Path(temporary, "none.bag"), "--topic", TOPIC],
                     ["No such file or directory"], ""),
                    (["--bag", bag, "--topic", TOPIC],
                     ["--bag needs Python's rosbag module", "python3-rosbag"], str(hidden))):
                with self.subTest(args=args, pythonpath=pythonpath):
                    answer = run(FOLDER_EXAMPLE, "--map", "bad-bag", *args,
                                 server=self.server.target, pythonpath=pythonpath)
                    self.assert_one_line_error(answer, FOLDER_EXAMPLE, *fragments)
            for args, message in (([CORRIDOR, "--bag", bag], "give either a folder of images "
                                   "or --bag FILE --topic TOPIC"),
                                  ([CORRIDOR, "--topic", TOPIC], "--topic goes with --bag")):
                with self.subTest(args=args):
                    answer = run(FOLDER_EXAMPLE, "--map", "bad-bag", *args,
                                 server=self.server.target)
                    self.assertEqual(answer.returncode, 2, answer.stderr)
                    self.assertIn(f"stream_folder.py: error: {message}", answer.stderr)
        with RecognitionClient(self.server.target) as client:
            self.assertNotIn("bad-bag", [m.name for m in client.list_maps()])

    def test_a_folder_that_does_not_exist_is_one_line(self):
        missing = SOURCE / "tests" / "data" / "no-such-folder"
        for example, args in ((CORRIDOR_EXAMPLE, [missing, *SETTINGS]),
                              (FOLDER_EXAMPLE, ["--map", "missing", missing])):
            with self.subTest(example.name):
                self.assert_one_line_error(run(example, *args, server=self.server.target),
                                           example, f"{missing}: no such folder")

    def test_a_folder_without_images_is_one_line(self):
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as folder:
            Path(folder, "notes.txt").write_text("no image here", encoding="utf-8")
            for example, args in ((CORRIDOR_EXAMPLE, [folder]),
                                  (FOLDER_EXAMPLE, ["--map", "empty", folder])):
                with self.subTest(example.name):
                    self.assert_one_line_error(run(example, *args, server=self.server.target),
                                               example, f"{folder}: no .jpg, .jpeg or .png image")
        with RecognitionClient(self.server.target) as client:
            self.assertNotIn("empty", [m.name for m in client.list_maps()])

    def test_bad_settings_are_a_usage_error(self):
        for setting, message in (("foo=1", 'no field named "foo"'),
                                 ("temporal_matches=x", "temporal_matches"),
                                 ("recent_frames", "expected KEY=VALUE")):
            with self.subTest(setting):
                answer = run(CORRIDOR_EXAMPLE, CORRIDOR, setting, server=self.server.target)
                self.assertEqual(answer.returncode, 2, answer.stderr)
                self.assertTrue(answer.stderr.startswith("usage: stream_corridor.py "))
                self.assertIn(f"error: argument KEY=VALUE: {setting}: ", answer.stderr)
                self.assertIn(message, answer.stderr)
                self.assertNotIn("Traceback", answer.stderr)

    def test_a_server_that_is_not_there_is_one_line_naming_it_and_how_to_start_one(self):
        nowhere = f"127.0.0.1:{free_port()}"  # nothing listens there
        for example, args, server in (
                (CORRIDOR_EXAMPLE, [CORRIDOR], nowhere),  # from RECOG_SERVER
                (CORRIDOR_EXAMPLE, ["--server", nowhere, CORRIDOR], ""),
                (FOLDER_EXAMPLE, ["--map", "lab", CORRIDOR], nowhere),
                (FOLDER_EXAMPLE, ["--server", nowhere, "--map", "lab", CORRIDOR], "")):
            with self.subTest(example=example.name, args=args):
                self.assert_one_line_error(run(example, *args, server=server), example,
                                           f"cannot reach recogd at {nowhere} ",
                                           "`bash scripts/run.sh`")


if __name__ == "__main__":
    unittest.main(verbosity=2)
