"""The examples as a first-time user runs them: examples/stream_corridor.py and stream_folder.py.

Each example runs as its own process with this interpreter (PYTHONPATH has the built package),
against a real recogd on a free port or against a port where nothing listens. Checked: the usage
without arguments (exit 2) and with --help (exit 0); on tests/data/corridor, with the settings
client/python/README.md gives, the loop lines and the summary line, and that the README shows that
very command and output; without the settings, the summary and the hint why there is no loop;
stream_folder's loop and summary lines; and one line on stderr, exit 1 and no traceback for a
folder that does not exist, a folder without images, a map that exists, a frame that is not an
image (stream_corridor names it and goes on: exit 0) and a server that is not there (naming its
address and `bash scripts/run.sh`); bad settings are a usage error (exit 2).

--bag, read by `recog bag extract` (examples/bag_frames.py): bags of tests/data/corridor written
by tests/testing/write_bag.py (ROS 1; JPEG bytes; mono8 pixels recorded last frame first) give
the folder's loops with the same inliers and their stamps are the frames' times (skipped without
Python's rosbag, which writes them); the ROS 2 fixtures of tests/data/bags (MCAP, zstd, lz4,
unchunked and unindexed; the rosbag2 sqlite3 folder and its .db3 file), raw and compressed, give
the same loops with their stamps in both examples, and the server keeps those stamps as the
frames' timestamps; stream_corridor's hint for a bag counts seconds; and one line on stderr, exit
1, no map created, no temporary folder left, for a bag without --topic (its image topics listed),
a topic it does not have (its topics listed), an unsupported encoding, a file that is not a bag,
a missing file and a missing recog (how to build it or pass --recog).

Environment (ctest sets it): RECOGD, RECOG (the recog binary, given to the examples as RECOG_BIN;
default: the checkout's build/bin/recog), RECOG_SOURCE_DIR, PYTHONPATH. Exits with 77 (skipped) when
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
#: The recog binary the examples read bags with.
RECOG = Path(os.environ.get("RECOG") or SOURCE / "build" / "bin" / "recog")
#: ROS 1 bags: written by this interpreter (it needs Debian's python3-rosbag), frames 1 s apart.
WRITE_BAG = SOURCE / "tests" / "testing" / "write_bag.py"
HAVE_ROSBAG = importlib.util.find_spec("rosbag") is not None
TOPIC = "/camera/image_raw"
#: ROS 2 bags written by real writers (tests/data/bags/README.md): 6 frames 64x48 at 10 Hz from
#: 1700000000 s, the same pixels raw (mono8 Image) and compressed (PNG).
BAGS = SOURCE / "tests" / "data" / "bags"
FIXTURE_TOPICS = ("/camera/image_raw", "/camera/image_raw/compressed")
FIXTURE_STAMPS = [1700000000 + k / 10 for k in range(6)]
#: The fixture's frames give loops once tau_c leaves out only the frame before (0.1 s).
FIXTURE_SETTINGS = {"temporal_matches": 0, "recent_frames": 1, "recent_seconds": 0.15}
#: SETTINGS for frames with timestamps 1 s apart: tau_c leaves out the frame before, as
#: recent_frames=1 does for frames without.
BAG_SETTINGS = {"temporal_matches": 0, "recent_frames": 1, "recent_seconds": 1.5}
#: The command the README documents, from the repository's root.
README_COMMAND = ("client/python/examples/stream_corridor.py tests/data/corridor "
                  "temporal_matches=0 recent_frames=1")


def run(example: Path, *args: str, server: str = "",
        **environment: str) -> subprocess.CompletedProcess:
    """Runs ``example`` with ``args`` from the repository's root, RECOG_SERVER = ``server``,
    RECOG_BIN = RECOG, and ``environment`` on top (a value None removes the variable)."""
    environment = {**os.environ, "RECOG_SERVER": server, "RECOG_BIN": str(RECOG), **environment}
    environment = {name: value for name, value in environment.items() if value is not None}
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
    def test_a_ros1_bag_that_cannot_be_streamed_is_one_line(self):
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as temporary:
            bag = write_bag(Path(temporary, "corridor.bag"), "--encoding", "jpeg")
            yuv = write_bag(Path(temporary, "yuv.bag"), "--encoding", "yuv422")
            for args, fragments in (
                    (["--bag", bag, "--topic", "/cam"],
                     [f"bag '{bag}' has no topic /cam", f"its topics: {TOPIC} "
                      "(sensor_msgs/CompressedImage, 4 messages)"]),
                    (["--bag", bag], [f"{bag}: give --topic, one of its image topics: {TOPIC} "
                                      "(sensor_msgs/CompressedImage, jpeg 512x384, 4 messages)"]),
                    (["--bag", yuv, "--topic", TOPIC],
                     ["encoding 'yuv422' is not supported", "stamp 1000.000000000"])):
                with self.subTest(args=args):
                    answer = run(FOLDER_EXAMPLE, "--map", "bad-bag", *args,
                                 server=self.server.target)
                    self.assert_one_line_error(answer, FOLDER_EXAMPLE, *fragments)
        with RecognitionClient(self.server.target) as client:
            self.assertNotIn("bad-bag", [m.name for m in client.list_maps()])

    @unittest.skipUnless(RECOG.is_file(), f"no recog at {RECOG}")
    def test_the_ros2_fixtures_give_the_same_loops_with_their_stamps_in_both_examples(self):
        bags = [BAGS / name for name in ("fixture.mcap", "fixture_lz4.mcap", "fixture_nochunk.mcap",
                                         "fixture_noindex.mcap", "fixture_cdr_be.mcap",
                                         "fixture_sqlite3", "fixture_sqlite3/fixture_0.db3")]
        first = None
        for number, (bag, topic) in enumerate((bag, topic) for bag in bags
                                              for topic in FIXTURE_TOPICS):
            with self.subTest(bag=bag.name, topic=topic):
                with RecognitionClient(self.server.target) as client:
                    client.create_map(f"fixture-{number}", FIXTURE_SETTINGS)
                answer = run(FOLDER_EXAMPLE, "--map", f"fixture-{number}", "--bag", bag,
                             "--topic", topic, server=self.server.target)
                self.assertEqual(answer.returncode, 0, answer.stderr)
                self.assertEqual(answer.stderr, "")
                lines = answer.stdout.replace(f"'fixture-{number}'", "'fixture'").splitlines()
                if first is None:  # the raw frames of fixture.mcap
                    first = lines
                    self.assertRegex(lines[0], r"^frame 2 \(stamp 1700000000\.200\) closes a loop "
                                     r"with frame 0 \(stamp 1700000000\.000\): \d+ inliers, ")
                    self.assertRegex(lines[-1], r"^6 frames streamed into map 'fixture', [1-5] "
                                     r"loops?$")
                self.assertEqual(lines, first)  # every kind of bag; raw and PNG the same pixels
        # stream_corridor: the same loops, named by their stamps.
        loops = [re.sub(r"^frame \d+ \((stamp [\d.]+)\) closes a loop with frame \d+ "
                        r"\((stamp [\d.]+)\): .*", r"\1 revisits \2", line) for line in first[:-1]]
        settings = [f"{key}={value}" for key, value in FIXTURE_SETTINGS.items()]
        for bag in (BAGS / "fixture.mcap", BAGS / "fixture_sqlite3"):
            with self.subTest(example=CORRIDOR_EXAMPLE.name, bag=bag.name):
                answer = run(CORRIDOR_EXAMPLE, "--map", f"fixture-corridor-{bag.stem}", "--bag",
                             bag, "--topic", FIXTURE_TOPICS[0], *settings,
                             server=self.server.target)
                self.assertEqual(answer.returncode, 0, answer.stderr)
                self.assertEqual(answer.stderr, "")
                self.assertEqual(answer.stdout.splitlines(),
                                 loops + [f"6 frames, {len(loops)} loop"
                                          + ("" if len(loops) == 1 else "s")])

    @unittest.skipUnless(RECOG.is_file(), f"no recog at {RECOG}")
    def test_the_server_keeps_a_ros2_bags_stamps_as_the_frames_timestamps(self):
        sys.path.insert(0, str(EXAMPLES))
        try:
            import bag_frames  # pylint: disable=import-outside-toplevel
        finally:
            sys.path.remove(str(EXAMPLES))
        with RecognitionClient(self.server.target) as client:
            client.create_map("fixture-stamps", FIXTURE_SETTINGS)
        answer = run(FOLDER_EXAMPLE, "--map", "fixture-stamps", "--bag", BAGS / "fixture.mcap",
                     "--topic", FIXTURE_TOPICS[1], server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        with bag_frames.extract(BAGS / "fixture.mcap", FIXTURE_TOPICS[1], str(RECOG)) as bag, \
                RecognitionClient(self.server.target) as client:
            self.assertEqual([frame.path.suffix for frame in bag.frames], [".png"] * 6)
            # rgb.txt has 9 decimals; a double at 1.7e9 s holds about 0.2 us.
            for frame, stamp in zip(bag.frames, FIXTURE_STAMPS, strict=True):
                self.assertAlmostEqual(frame.stamp, stamp, delta=1e-6)
            for number, frame in enumerate(bag.frames):  # each finds itself, with its stamp
                result = client.query_place("fixture-stamps", str(frame.path)).result
                self.assertEqual(result.match_frame_id, number)
                self.assertAlmostEqual(result.match_timestamp, FIXTURE_STAMPS[number], delta=1e-6)

    @unittest.skipUnless(RECOG.is_file(), f"no recog at {RECOG}")
    def test_for_a_bag_the_corridors_hint_counts_seconds(self):
        answer = run(CORRIDOR_EXAMPLE, "--map", "fixture-defaults", "--bag",
                     BAGS / "fixture.mcap", "--topic", FIXTURE_TOPICS[0],
                     server=self.server.target)
        self.assertEqual(answer.returncode, 0, answer.stderr)
        self.assertEqual(answer.stdout, "6 frames, 0 loops\n")
        self.assertEqual(answer.stderr, "stream_corridor: no loop can be found in a bag of 0.5 s "
                         "with recent_seconds=20 (a frame's match must be more than 20 s older); "
                         "try temporal_matches=0 recent_seconds=0.15\n")

    @unittest.skipUnless(RECOG.is_file(), f"no recog at {RECOG}")
    def test_a_bag_that_cannot_be_streamed_is_one_line(self):
        sqlite = BAGS / "fixture_sqlite3"
        mcap = BAGS / "fixture.mcap"
        topics = ("its topics: /camera/camera_info (sensor_msgs/msg/CameraInfo, 6 messages), "
                  "/camera/depth/image_raw (sensor_msgs/msg/Image, 6 messages)")
        image_topics = (
            f"{sqlite}: give --topic, one of its image topics: /camera/depth/image_raw "
            "(sensor_msgs/msg/Image, 16UC1 64x48, 6 messages), /camera/depth/image_raw/"
            "compressedDepth (sensor_msgs/msg/CompressedImage, 16UC1; compressedDepth png 64x48, "
            "6 messages), /camera/image_raw (sensor_msgs/msg/Image, mono8 64x48, 6 messages), "
            "/camera/image_raw/compressed (sensor_msgs/msg/CompressedImage, mono8; png "
            "compressed mono8 64x48, 6 messages)")
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as temporary:
            not_a_bag = Path(temporary, "notes.mcap")
            not_a_bag.write_text("not a bag", encoding="utf-8")
            missing = Path(temporary, "none.mcap")
            scratch = Path(temporary, "tmp")  # the examples' TMPDIR: left empty
            scratch.mkdir()
            for example in (FOLDER_EXAMPLE, CORRIDOR_EXAMPLE):
                for args, fragments in (
                        (["--bag", sqlite], [image_topics]),
                        (["--bag", mcap, "--topic", "/cam"], [f"bag '{mcap}' has no topic /cam",
                                                              topics]),
                        (["--bag", mcap, "--topic", "/camera/camera_info"],
                         ["/camera/camera_info", "is sensor_msgs/msg/CameraInfo; expected "
                          "sensor_msgs/Image or sensor_msgs/CompressedImage"]),
                        (["--bag", sqlite, "--topic", "/camera/depth/image_raw"],
                         ["encoding '16UC1' (a depth encoding) is not supported"]),
                        (["--bag", not_a_bag, "--topic", TOPIC], [f"'{not_a_bag}' is not a bag"]),
                        (["--bag", not_a_bag], [f"'{not_a_bag}' is not a bag"]),
                        (["--bag", CORRIDOR / "1.jpg", "--topic", TOPIC], ["is not a bag"]),
                        (["--bag", missing, "--topic", TOPIC], [f"bag '{missing}' does not exist"]),
                        (["--bag", mcap, "--topic", TOPIC, "--recog", missing],
                         [f"{missing} (from --recog) is not an executable file"])):
                    with self.subTest(example=example.name, args=args):
                        answer = run(example, "--map", "bad-bag", *args,
                                     server=self.server.target, TMPDIR=str(scratch))
                        self.assert_one_line_error(answer, example, *fragments)
                        self.assertEqual(list(scratch.iterdir()), [])
                with self.subTest(example=example.name, variable="RECOG_BIN"):
                    answer = run(example, "--map", "bad-bag", "--bag", mcap, "--topic", TOPIC,
                                 server=self.server.target, RECOG_BIN=str(missing))
                    self.assert_one_line_error(answer, example,
                                               f"{missing} (from RECOG_BIN) is not an executable")
                for args, message in (
                        ([CORRIDOR, "--bag", mcap],
                         "give either a folder of images or --bag BAG --topic TOPIC"),
                        ([CORRIDOR, "--topic", TOPIC], "--topic goes with --bag"),
                        ([CORRIDOR, "--recog", RECOG], "--recog goes with --bag")):
                    with self.subTest(example=example.name, args=args):
                        answer = run(example, "--map", "bad-bag", *args,
                                     server=self.server.target)
                        self.assertEqual(answer.returncode, 2, answer.stderr)
                        self.assertIn(f"{example.name}: error: {message}", answer.stderr)
            # A good bag leaves no temporary folder either.
            answer = run(FOLDER_EXAMPLE, "--map", "fixture-scratch", "--bag", mcap, "--topic",
                         FIXTURE_TOPICS[0], server=self.server.target, TMPDIR=str(scratch))
            self.assertEqual(answer.returncode, 0, answer.stderr)
            self.assertEqual(list(scratch.iterdir()), [])
        with RecognitionClient(self.server.target) as client:
            self.assertNotIn("bad-bag", [m.name for m in client.list_maps()])

    def test_without_recog_a_bag_is_one_line_saying_how_to_build_it(self):
        with tempfile.TemporaryDirectory(prefix="recog-examples-") as temporary:
            # The examples outside the checkout (no build/bin/recog next to them), no recog on
            # PATH, no RECOG_BIN.
            examples = Path(temporary, "client", "python", "examples")
            shutil.copytree(EXAMPLES, examples, ignore=shutil.ignore_patterns("__pycache__"))
            empty = Path(temporary, "bin")
            empty.mkdir()
            for example in (FOLDER_EXAMPLE, CORRIDOR_EXAMPLE):
                with self.subTest(example.name):
                    copy = examples / example.name
                    answer = run(copy, "--map", "no-recog", "--bag", BAGS / "fixture.mcap",
                                 "--topic", TOPIC, server=self.server.target, RECOG_BIN=None,
                                 PATH=str(empty))
                    self.assert_one_line_error(
                        answer, copy, "a bag is read by recog, the project's CLI, and there is "
                        f"none on PATH nor at {Path(temporary).resolve()}/build/bin/recog",
                        "`bash scripts/build.sh recog`", "--recog or RECOG_BIN")
        with RecognitionClient(self.server.target) as client:
            self.assertNotIn("no-recog", [m.name for m in client.list_maps()])

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
