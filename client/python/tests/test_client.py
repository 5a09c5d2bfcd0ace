"""Tests of the Python client against the real recogd.

The server binary is taken from the environment variable RECOGD, the CLI (to build a model) from
RECOG and the corridor images from RECOG_SOURCE_DIR/tests/data/corridor; the package recog_client
(built into <build>/python by the target recog_python_package) must be on PYTHONPATH (ctest sets
all of them: ``ctest -R python``). Exits with 77 (skipped) when Python's grpc or protobuf modules
are missing.
"""

import hashlib
import math
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time
import unittest
import unittest.mock
import zlib
from pathlib import Path

try:
    import grpc
    from recogd_process import Recogd
    from waiting import wait_until
    from recog_client import (AlreadyExists, Cancelled, InvalidArgument, NotFound,
                              PermissionDenied, RecognitionClient, ResultOptions,
                              Unauthenticated, Unavailable, make_features, make_frame,
                              make_intrinsics, make_rig_frame, object_pb2, place_pb2,
                              repository_pb2, rig_camera, rig_view)
except ModuleNotFoundError as missing:
    if missing.name.split(".")[0] not in ("grpc", "google"):
        raise  # the package is not on PYTHONPATH: an error, not a skip
    print(f"SKIP: {missing} (Debian: apt-get install python3-grpcio python3-protobuf)",
          file=sys.stderr)
    sys.exit(77)
import cv2  # noqa: E402  (python3-opencv and python3-numpy, in scripts/install_deps.sh)
import numpy  # noqa: E402

CORRIDOR = Path(os.environ.get("RECOG_SOURCE_DIR", ".")) / "tests" / "data" / "corridor"
TLS = Path(os.environ.get("RECOG_SOURCE_DIR", ".")) / "tests" / "data" / "tls"
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "stream_folder.py"
CORRIDOR_CAMERA = (500.0, 500.0, 256.0, 192.0)  # fx fy cx cy of the 512x384 corridor images


def corridor(n: int) -> Path:
    """The path of tests/data/corridor/<n>.jpg (n = 1, 20, 41, 60)."""
    return CORRIDOR / f"{n}.jpg"


def depth_png(width: int, height: int, millimetres: int) -> bytes:
    """A 16-bit grey PNG of a constant depth: a plane facing the camera."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data)))
    rows = (b"\x00" + struct.pack(">H", millimetres) * width) * height  # filter 0 on every row
    header = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)  # 16-bit grey
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows))
            + chunk(b"IEND", b""))


def noise(seed: int, size: tuple[int, int] = (512, 384)) -> numpy.ndarray:
    """A grey image of blurred random blocks (``size`` = (width, height)) that matches no place
    and no other seed's image."""
    blocks = numpy.random.default_rng(seed).integers(0, 256, (48, 64), dtype=numpy.uint8)
    return cv2.GaussianBlur(cv2.resize(blocks, size, interpolation=cv2.INTER_NEAREST), (3, 3), 0)


def front_and_rear_rig() -> list:
    """A rig of two corridor cameras 0.8 m apart on the body's z axis, back to back: "front" looks
    along +z, "rear" along -z (turned half round the y axis)."""
    return [rig_camera("front", (512, 384), CORRIDOR_CAMERA, translation=(0, 0, 0.4)),
            rig_camera("rear", (512, 384), CORRIDOR_CAMERA,
                       rotation=numpy.diag([-1.0, 1.0, -1.0]), translation=(0, 0, -0.4))]


class RecognitionClientTest(unittest.TestCase):
    """One plaintext recogd without tokens for the whole class."""

    @classmethod
    def setUpClass(cls):
        """Starts recogd and waits until it serves."""
        cls.server = Recogd()
        cls.target = cls.server.target
        cls.server.wait_until_serving()
        cls.client = RecognitionClient(cls.target)

    @classmethod
    def tearDownClass(cls):
        """Stops recogd and checks that it exits with 0."""
        cls.client.close()
        cls.server.stop()

    def assert_raises(self, error: type, call, *args):
        """Checks that ``call(*args)`` raises ``error`` (a RecogError) with the server's message."""
        with self.assertRaises(error) as raised:
            call(*args)
        self.assertEqual(raised.exception.code, error.code)
        self.assertTrue(raised.exception.details)

    def test_map_lifecycle(self):
        info = self.client.create_map("lifecycle", {"temporal_matches": 2})
        self.assertEqual(info.name, "lifecycle")
        self.assertEqual(info.settings.temporal_matches, 2)
        self.assertEqual(info.frames, 0)
        self.assert_raises(AlreadyExists, self.client.create_map, "lifecycle")
        self.assertIn("lifecycle", [m.name for m in self.client.list_maps()])
        self.assertEqual(self.client.get_map("lifecycle").id, info.id)
        self.assertEqual(self.client.delete_map("lifecycle"), 0)
        self.assert_raises(NotFound, self.client.get_map, "lifecycle")
        self.assert_raises(NotFound, self.client.delete_map, "lifecycle")

    def test_a_keyframe_map_starts_from_the_keyframes_preset(self):
        info = self.client.create_map("keyframes", {"preset": "keyframes"})
        self.assertEqual(info.settings.preset, "keyframes")
        self.assertEqual(info.settings.recent_frames, 3)  # the preset's tau_c
        self.assertEqual(self.client.create_map("video").settings.preset, "default")
        self.assert_raises(InvalidArgument, self.client.create_map, "odd", {"preset": "sideways"})

    def test_list_maps_reads_every_page(self):
        names = ["page-a", "page-b", "page-c"]
        for name in names:
            self.client.create_map(name)
        listed = [m.name for m in self.client.list_maps(page_size=2)]
        self.assertEqual(listed, sorted(listed))
        self.assertTrue(set(names) <= set(listed), listed)

    def test_added_place_is_found_by_a_query_that_changes_nothing(self):
        self.client.create_map("hall")
        for frame_id, n in enumerate([1, 20, 41, 60]):
            added = self.client.add_frame("hall", corridor(n), timestamp=n)
            self.assertEqual(added.frame_id, frame_id)
            self.assertGreater(added.num_features, 300)
        response = self.client.query_place("hall", corridor(41).read_bytes())
        self.assertEqual(response.result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(response.result.match_frame_id, 2)
        self.assertEqual(response.result.match_timestamp, 41)
        self.assertFalse(response.result.HasField("frame_id"))  # nothing was added
        self.assertEqual(self.client.get_map("hall").frames, 4)

    def test_a_clock_that_starts_at_zero_keeps_its_first_frame_recent(self):
        # KITTI's times start at 0.0: a time, not "unknown". Every frame of this tour lies within
        # the map's recent_seconds (20 s) of the others, so none is a candidate, the first frame
        # included (a revisit of frame 0 two seconds later is no loop).
        self.assertTrue(make_frame(corridor(1), timestamp=0.0).HasField("timestamp"))
        self.assertFalse(make_frame(corridor(1)).HasField("timestamp"))
        frames = [make_frame(corridor(n), timestamp=float(t)) for t, n in enumerate([1, 20, 1, 20])]
        answers = list(self.client.stream_frames(
            "kitti", frames, settings={"temporal_matches": 0, "recent_frames": 1}))
        self.assertEqual(len(answers), 4)
        for answer in answers:
            self.assertTrue(answer.HasField("result"), answer.error.message)
            self.assertFalse(answer.result.HasField("match_frame_id"), answer.result)
        # Without timestamps recent_frames (1) applies: the revisit of frame 0 is found.
        untimed = list(self.client.stream_frames(
            "untimed", [corridor(n) for n in [1, 20, 1]],
            settings={"temporal_matches": 0, "recent_frames": 1}))
        self.assertEqual(untimed[2].result.match_frame_id, 0)
        self.assertFalse(untimed[2].result.HasField("match_timestamp"))

    def test_a_frame_with_depth_gives_metric_loops_and_bad_depth_is_refused(self):
        self.client.create_map("rgbd")
        k = (500, 500, 256, 192)  # the corridor images are 512x384
        added = self.client.add_frame(
            "rgbd", make_frame(corridor(41), intrinsics=k, depth=depth_png(512, 384, 2000)))
        self.assertEqual(added.frame_id, 0)
        result = self.client.query_place("rgbd", make_frame(corridor(41), intrinsics=k)).result
        self.assertEqual(result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertTrue(result.metric.checked)
        self.assertTrue(result.metric.verified)
        self.assertGreaterEqual(result.metric.inliers, 12)
        self.assertEqual(len(result.metric.covariance), 36)
        self.assertLess(max(abs(v) for v in result.metric.pose.translation), 0.01)  # same view
        bad = {"16-bit": make_frame(corridor(20), intrinsics=k, depth=corridor(20)),  # 8-bit
               "aligned": make_frame(corridor(20), intrinsics=k, depth=depth_png(256, 192, 2000))}
        for words, frame in bad.items():
            with self.assertRaises(InvalidArgument) as refused:
                self.client.add_frame("rgbd", frame)
            self.assertIn(words, refused.exception.details)
        with self.assertRaises(InvalidArgument):
            make_frame(corridor(20), intrinsics=k, right=corridor(60))  # no baseline
        with self.assertRaises(ValueError):  # InvalidArgument is a ValueError
            make_frame(corridor(20), depth=depth_png(512, 384, 2000))  # no intrinsics
        self.assertEqual(self.client.get_map("rgbd").frames, 1)

    def test_a_slam_gets_its_keyframe_ids_candidates_and_inliers_and_culls_keyframes(self):
        self.client.create_map("slam")
        for n in (1, 20, 41, 60):
            added = self.client.add_frame("slam", corridor(n), client_frame_id=f"kf-{n}")
            self.assertEqual(added.client_frame_id, f"kf-{n}")
        response = self.client.query_place(
            "slam", corridor(41).read_bytes(),
            result_options={"top_k": 2, "include_correspondences": True})
        result = response.result
        self.assertEqual(result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(result.match_frame_id, 2)
        self.assertEqual(result.match_client_frame_id, "kf-41")
        self.assertEqual(len(result.candidates), 2)
        self.assertEqual(result.candidates[0].frame_id, 2)
        self.assertEqual(result.candidates[0].client_frame_id, "kf-41")
        self.assertEqual(result.candidates[0].inliers, result.inliers)
        self.assertGreaterEqual(result.candidates[0].score, result.candidates[1].score)
        self.assertFalse(result.candidates[1].HasField("inliers"))
        self.assertEqual(len(result.inlier_correspondences), result.inliers)
        self.assert_raises(InvalidArgument, self.client.query_place, "slam",
                         corridor(41).read_bytes(), False, {"top_k": 51})

        self.assertEqual(self.client.remove_frame("slam", frame_id=2), [2])
        self.assertEqual(self.client.remove_frame("slam", client_frame_id="kf-60"), [3])
        self.assert_raises(NotFound, self.client.remove_frame, "slam", 2)
        self.assert_raises(NotFound, self.client.remove_frame, "nowhere", 0)
        with self.assertRaises(InvalidArgument):
            self.client.remove_frame("slam")
        result = self.client.query_place("slam", corridor(41).read_bytes(),
                                         result_options={"top_k": 50}).result
        self.assertNotEqual(result.match_frame_id, 2)
        self.assertTrue(all(c.frame_id < 2 for c in result.candidates), result.candidates)
        self.assertEqual(self.client.get_map("slam").frames, 2)

    def test_result_options_give_the_fundamental_matrix_and_the_relative_pose(self):
        self.client.create_map("geometry")
        k = (500, 500, 256, 192)
        for n in (1, 20):  # 41 revisits 1 from another view (the same image has no pose)
            self.client.add_frame("geometry", make_frame(corridor(n), intrinsics=k))
        plain = self.client.query_place("geometry", make_frame(corridor(41), intrinsics=k)).result
        self.assertEqual(plain.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(len(plain.fundamental), 0)
        self.assertFalse(plain.HasField("relative_pose"))
        options = ResultOptions(include_fundamental=True, include_relative_pose=True)
        full = self.client.query_place("geometry", make_frame(corridor(41), intrinsics=k),
                                       result_options=options).result
        self.assertEqual(full.match_frame_id, 0)
        self.assertEqual(len(full.fundamental), 9)
        self.assertEqual(len(full.relative_pose.rotation), 9)
        self.assertAlmostEqual(sum(v * v for v in full.relative_pose.translation), 1.0, places=6)

    def test_a_fisheye_camera_s_loops_come_back_in_the_pinhole_image_of_its_matrix(self):
        # The same frames through a pinhole and through an ideal fisheye (r = f theta) of the same
        # matrix: the server extracts the same keypoints, and moves the fisheye's to the pinhole
        # image, where a keypoint r pixels off the principal point lies at f tan(r / f).
        options = ResultOptions(include_correspondences=True)
        found = {}
        for name, lens in (("pinhole", "radtan"), ("fisheye", "equidistant")):
            camera = make_intrinsics((500, 500, 256, 192) + ((0, 0, 0, 0) if lens != "radtan"
                                                             else ()), lens=lens)
            self.client.create_map(name)
            for n in (1, 20):
                self.client.add_frame(name, make_frame(corridor(n), intrinsics=camera))
            result = self.client.query_place(name, make_frame(corridor(41), intrinsics=camera),
                                             result_options=options).result
            self.assertEqual(result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
            found[name] = {c.query_index: (c.query_x, c.query_y)
                           for c in result.inlier_correspondences}
        common = set(found["pinhole"]) & set(found["fisheye"])
        self.assertGreater(len(common), 10)
        for index in common:
            (x, y), (moved_x, moved_y) = found["pinhole"][index], found["fisheye"][index]
            r = math.hypot(x - 256, y - 192)
            scale = 500 * math.tan(r / 500) / r if r > 0 else 1
            self.assertAlmostEqual(moved_x, 256 + (x - 256) * scale, delta=0.01)
            self.assertAlmostEqual(moved_y, 192 + (y - 192) * scale, delta=0.01)
        with self.assertRaises(InvalidArgument):
            make_intrinsics((500, 500, 256, 192), lens="omni")
        wrong_count = make_intrinsics((500, 500, 256, 192, 0.1), lens="double_sphere")
        self.assert_raises(InvalidArgument, self.client.query_place, "fisheye",
                           make_frame(corridor(41), intrinsics=wrong_count))

    def test_a_low_resolution_camera_s_frames_are_enlarged_by_the_server_and_find_the_place(self):
        self.client.create_map("small-frames")
        small = {n: cv2.resize(cv2.imread(str(corridor(n)), cv2.IMREAD_GRAYSCALE), (128, 96),
                               interpolation=cv2.INTER_AREA) for n in (1, 20, 41, 60)}
        for n, image in small.items():
            added = self.client.add_frame("small-frames", image)
            # ORB alone finds a few dozen corners in 128x96; the server enlarges the frame first
            self.assertGreater(added.num_features, 100)
        self.assertEqual(self.client.query_place("small-frames", small[41]).result.match_frame_id,
                         2)
        # the SLAM's covisible keyframes are left out
        left_out = self.client.query_place("small-frames",
                                           make_frame(small[41], exclude_frame_ids=[2])).result
        self.assertNotEqual(left_out.match_frame_id, 2)
        self.assertNotIn(2, [c.frame_id for c in left_out.candidates])

    def test_a_robot_finds_another_robot_s_place_across_their_group(self):
        for robot in ("robot-a", "robot-b"):
            self.assertEqual(self.client.create_map(robot, {"group": "fleet"}).settings.group,
                             "fleet")
        for n in (1, 20):
            self.client.add_frame("robot-a", corridor(n), client_frame_id=f"a-{n}")
        answer = self.client.query_place("robot-b", corridor(41), add_frame=True,
                                         search_group="fleet")
        self.assertEqual([m.map for m in answer.inter_map], ["robot-a"])
        self.assertEqual(answer.inter_map[0].result.match_client_frame_id, "a-1")
        self.assertEqual(answer.result.frame_id, 0)  # robot B's own map got the frame
        answers = list(self.client.stream_frames("robot-b", [corridor(41)],
                                                 search_maps=["robot-a"]))
        self.assertEqual(answers[0].inter_map[0].result.match_frame_id, 0)
        with self.assertRaises(NotFound) as unknown:
            self.client.query_place("robot-b", corridor(41), add_frame=True,
                                    search_maps=["robot-z"])
        self.assertIn("robot-z", str(unknown.exception))
        self.assertEqual(self.client.get_map("robot-b").frames, 2)  # the refused frame was not added

    def test_a_kidnapped_robot_relocalizes_in_its_group_from_a_few_frames(self):
        for robot in ("lost-a", "lost-b"):
            self.client.create_map(robot, {"group": "lost"})
        self.client.add_frame("lost-a", corridor(1), client_frame_id="a-1")
        self.client.add_frame("lost-b", corridor(60))
        frames = [make_frame(corridor(41), client_frame_id="q-41"), corridor(60)]
        answer = self.client.relocalize(frames, group="lost")
        places = {place.map: place for place in answer.places}
        self.assertEqual(set(places), {"lost-a", "lost-b"})
        a = places["lost-a"]
        self.assertEqual((a.frame_index, a.client_frame_id), (0, "q-41"))
        self.assertEqual(a.result.match_client_frame_id, "a-1")
        self.assertEqual(a.result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(places["lost-b"].frame_index, 1)  # lost-b has seen frame 60 only
        best = self.client.relocalize(frames, group="lost", max_results=1).places
        self.assertEqual([p.map for p in best], [answer.places[0].map])
        with self.assertRaises(NotFound) as unknown:
            self.client.relocalize(frames, maps=["robot-z"])
        self.assertIn("robot-z", str(unknown.exception))
        with self.assertRaises(InvalidArgument):
            self.client.relocalize([], maps=["lost-a"])
        self.assertEqual(self.client.get_map("lost-a").frames, 1)  # nothing was added

    def test_a_rig_s_rear_camera_finds_what_its_front_camera_saw(self):
        rig = front_and_rear_rig()
        self.client.create_map("rig", place_pb2.MapSettings(rig=rig, recent_frames=1))
        for i, n in enumerate((1, 20, 41)):
            # the front view of frame 20 has its depth (a plane 2 m away), for a metric loop
            front = corridor(n) if n != 20 else rig_view(corridor(n),
                                                         depth=depth_png(512, 384, 2000))
            frame = make_rig_frame({"front": front, "rear": noise(n)}, client_frame_id=f"rig-{n}")
            added = self.client.add_frame("rig", frame)
            self.assertEqual(added.frame_id, 2 * i)  # the id of its first camera image
        info = self.client.get_map("rig")
        self.assertEqual(info.frames, 3)
        self.assertEqual(list(info.settings.rig), rig)
        # The robot came back turned round: its rear camera sees what the front one saw.
        query = make_rig_frame({"front": noise(99), "rear": corridor(20)})
        result = self.client.query_place("rig", query).result
        self.assertEqual(result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual((result.match_frame_id, result.match_client_frame_id), (2, "rig-20"))
        self.assertEqual([(p.query_camera, p.match_camera) for p in result.rig.pairs],
                         [("rear", "front")])
        # The rear camera where the front one was: the body turned half round, in place.
        self.assertTrue(result.rig.metric)
        numpy.testing.assert_allclose(result.rig.body_pose.rotation,
                                      numpy.diag([-1.0, 1.0, -1.0]).ravel(), atol=1e-3)
        numpy.testing.assert_allclose(result.rig.body_pose.translation, [0, 0, 0], atol=0.01)
        self.assertEqual(self.client.get_map("rig").frames, 3)  # the query added nothing

    def test_a_rig_frame_missing_a_camera_or_of_another_size_is_refused_naming_the_camera(self):
        self.client.create_map("rig-refusals", {"rig": front_and_rear_rig()})
        self.client.add_frame("rig-refusals",
                              make_rig_frame({"front": corridor(1), "rear": noise(1)}))
        refused = {"'rear'": make_rig_frame({"front": corridor(20)}),
                   "rig camera 'rear'": make_rig_frame({"front": corridor(20),
                                                        "rear": noise(20, (320, 240))}),
                   "is a rig map": make_frame(corridor(20))}
        for words, frame in refused.items():
            with self.assertRaises(InvalidArgument) as raised:
                self.client.add_frame("rig-refusals", frame)
            self.assertIn(words, raised.exception.details)
        self.assertEqual(self.client.get_map("rig-refusals").frames, 1)
        self.client.create_map("no-rig")
        self.assert_raises(InvalidArgument, self.client.add_frame, "no-rig",
                           make_rig_frame({"front": corridor(1)}))
        self.assertEqual(self.client.get_map("no-rig").frames, 0)

    def test_rig_cameras_and_rig_frames_are_checked_before_they_are_sent(self):
        quarter = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # a quarter turn about z
        for rotation in (quarter, numpy.array(quarter), sum(quarter, [])):
            side = rig_camera("side", (512, 384), CORRIDOR_CAMERA, rotation=rotation)
            self.assertEqual(list(side.body_pose.rotation), [0, -1, 0, 1, 0, 0, 0, 0, 1])
        self.assertEqual(list(side.body_pose.translation), [0, 0, 0])
        self.assertEqual((side.width, side.height, side.intrinsics.cx), (512, 384, 256))
        distorted = rig_camera("side", (512, 384), CORRIDOR_CAMERA, distortion=(0.1, 0, 0, 0))
        self.assertEqual(list(distorted.intrinsics.distortion), [0.1, 0, 0, 0])
        with self.assertRaises(InvalidArgument):
            rig_camera("side", (512, 384), CORRIDOR_CAMERA, translation=(0.0, 0.4))
        with self.assertRaises(InvalidArgument):
            rig_camera("side", (512, 384), CORRIDOR_CAMERA, rotation=quarter[:2])
        with self.assertRaises(InvalidArgument):  # distortion in the intrinsics and apart
            rig_camera("side", (512, 384), (*CORRIDOR_CAMERA, 0.1, 0, 0, 0),
                       distortion=(0.1, 0, 0, 0))
        frame = make_rig_frame({"rear": corridor(1), "front": make_frame(noise(1))},
                               timestamp=0.0, client_frame_id="both", exclude_frame_ids=[2])
        self.assertEqual([view.camera_id for view in frame.views], ["rear", "front"])
        self.assertEqual(frame.views[1].raw_image.width, 512)
        self.assertIsNone(frame.WhichOneof("content"))
        self.assertEqual((frame.timestamp, frame.client_frame_id, list(frame.exclude_frame_ids)),
                         (0.0, "both", [2]))
        with self.assertRaises(InvalidArgument):
            make_rig_frame({})
        with self.assertRaises(InvalidArgument) as timed:
            make_rig_frame({"front": make_frame(corridor(1), timestamp=1.0)})
        self.assertIn("timestamp", timed.exception.details)
        with self.assertRaises(InvalidArgument):  # the camera's intrinsics come from the rig
            make_rig_frame({"front": make_frame(corridor(1), intrinsics=CORRIDOR_CAMERA)})
        with self.assertRaises(InvalidArgument):
            make_rig_frame({"front": make_frame(corridor(1), camera_id="rear")})
        with self.assertRaises(InvalidArgument):
            rig_view(corridor(1), depth=depth_png(512, 384, 2000), right=corridor(20), baseline=0.1)

    def test_a_rig_stream_creates_its_map_and_a_bad_camera_image_fails_its_frame_only(self):
        frames = [make_rig_frame({"front": corridor(1), "rear": noise(1)}),
                  make_rig_frame({"front": corridor(20), "rear": b"\xff\xd8 this is not a JPEG"}),
                  make_rig_frame({"front": corridor(20), "rear": noise(20)}),
                  make_rig_frame({"front": noise(2), "rear": corridor(1)})]
        settings = {"temporal_matches": 0, "recent_frames": 1, "rig": front_and_rear_rig()}
        answers = list(self.client.stream_frames("rig-stream", frames, settings=settings))
        self.assertEqual([answer.sequence for answer in answers], [0, 1, 2, 3])
        self.assertIn("rig camera 'rear'", answers[1].error.message)
        # the failed frame took no id
        self.assertEqual([answers[i].result.frame_id for i in (0, 2, 3)], [0, 2, 4])
        last = answers[3].result
        self.assertEqual(last.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(last.match_frame_id, 0)
        self.assertEqual(last.rig.pairs[0].query_camera, "rear")
        self.assertEqual(last.rig.pairs[0].match_camera, "front")
        info = self.client.get_map("rig-stream")
        self.assertEqual((info.frames, [c.name for c in info.settings.rig]), (3, ["front", "rear"]))

    def test_frames_from_numpy_arrays_and_from_client_side_features_find_the_place(self):
        self.client.create_map("arrays")
        for n in (1, 20, 41, 60):
            added = self.client.add_frame("arrays", cv2.imread(str(corridor(n))))  # BGR
            self.assertGreater(added.num_features, 300)
        grey = cv2.imread(str(corridor(41)), cv2.IMREAD_GRAYSCALE)
        self.assertEqual(self.client.query_place("arrays", grey).result.match_frame_id, 2)
        keypoints, descriptors = cv2.ORB_create(1000).detectAndCompute(grey, None)
        features = make_features(keypoints, descriptors, image_size=(512, 384))
        self.assertEqual(features.descriptor_bytes, 32)
        result = self.client.query_place("arrays", features).result
        self.assertEqual(result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(result.match_frame_id, 2)
        with self.assertRaises(InvalidArgument):
            make_frame(numpy.zeros((4, 4, 3), numpy.float32))  # not uint8
        with self.assertRaises(InvalidArgument):
            make_features(keypoints[:3], descriptors[:2])  # 2 descriptors for 3 keypoints

    def test_an_exception_of_the_frames_iterator_is_raised_as_itself(self):
        def frames():
            yield corridor(1)
            raise FileNotFoundError("the camera is gone")

        with self.assertRaises(FileNotFoundError):
            list(self.client.stream_frames("broken-camera", frames()))

    def test_health_and_an_online_checkpoint(self):
        self.assertEqual(self.client.check_health(), "SERVING")
        self.client.create_map("saved")
        self.client.add_frame("saved", corridor(1))
        with tempfile.TemporaryDirectory(prefix="recog-python-test-") as tmp:
            target = Path(tmp) / "checkpoint"
            seen = []
            manifest = self.client.checkpoint(target, lambda done, total: seen.append(done))
            self.assertGreaterEqual(manifest.maps, 1)
            self.assertEqual(sorted(p.name for p in target.iterdir()),
                             sorted(f.name for f in manifest.files))
            for file in manifest.files:
                self.assertEqual((target / file.name).stat().st_size, file.size_bytes)
            self.assertEqual(seen[-1], manifest.total_bytes)
            self.assertFalse((Path(tmp) / "checkpoint.part").exists())
            with self.assertRaises(AlreadyExists):
                self.client.checkpoint(target)
        # The checkpoint flushed the frame into a table file, which the check reads.
        report = self.client.verify_store()
        self.assertGreaterEqual(report.files, 1)
        self.assertGreater(report.bytes, 0)
        self.assertEqual(self.client.check_health("recog.store"), "SERVING")
        status = self.client.store_status()
        self.assertFalse(status.HasField("recovery"))  # the store opened whole
        self.assertEqual(status.last_check.error, "")
        self.assertEqual(status.last_check.files, report.files)

    def test_stream_answers_in_order_and_detects_the_revisit(self):
        frames = [corridor(n) for n in (1, 20, 41, 60, 1)]
        answers = list(self.client.stream_frames(
            "tour", frames, settings={"temporal_matches": 0, "recent_frames": 1}))
        self.assertEqual(len(answers), 5)
        for i, answer in enumerate(answers):
            self.assertEqual(answer.sequence, i)
            self.assertTrue(answer.HasField("result"), answer.error.message)
            self.assertEqual(answer.result.frame_id, i)
        self.assertEqual(answers[-1].result.status, place_pb2.LOOP_STATUS_LOOP_DETECTED)
        self.assertEqual(answers[-1].result.match_frame_id, 0)
        self.assertEqual(self.client.get_map("tour").frames, 5)

    def test_a_bad_frame_gets_its_error_and_the_stream_goes_on(self):
        frames = [b"\xff\xd8 this is not a JPEG", corridor(1)]
        answers = list(self.client.stream_frames("noisy", frames))
        self.assertEqual(len(answers), 2)
        self.assertTrue(answers[0].HasField("error"))
        self.assertEqual(answers[0].error.code, grpc.StatusCode.INVALID_ARGUMENT.value[0])
        self.assertTrue(answers[0].error.message)
        self.assertTrue(answers[1].HasField("result"), answers[1].error.message)
        self.assertEqual(answers[1].result.frame_id, 0)  # the failed frame added nothing

    def test_objects_and_models(self):
        self.assertEqual(list(self.client.list_models()), [])
        response = self.client.recognize_objects(corridor(1), (500.0, 500.0, 320.0, 240.0))
        self.assertEqual(len(response.objects), 0)
        self.assert_raises(NotFound, self.client.download_model, "nothing")
        self.assert_raises(NotFound, self.client.delete_model, "nothing")

    def test_objects_carry_inliers_and_covariance_when_asked(self):
        recog = os.environ.get("RECOG")
        if not recog:
            raise RuntimeError("set RECOG to the path of the recog binary")
        with tempfile.TemporaryDirectory(prefix="recog-python-test-") as tmp:
            model = Path(tmp) / "poster.robj"
            subprocess.run([recog, "model", "build", "--planar", str(corridor(1)), "--width",
                            "0.64", "--height", "0.48", "--name", "slam-poster", "-o",
                            str(model)], check=True, capture_output=True)
            uploaded = self.client.upload_model(model)
            model_bytes = model.read_bytes()
        try:
            self.assertEqual(self.client.download_model("slam-poster", uploaded.version),
                             model_bytes)
            camera = (500.0, 500.0, 256.0, 192.0)
            plain = self.client.recognize_objects(corridor(1), camera, names=["slam-poster"])
            full = self.client.recognize_objects(corridor(1), camera, names=["slam-poster"],
                                                 include_inliers=True, include_covariance=True)
            explained = self.client.recognize_objects(corridor(60), camera,
                                                      names=["slam-poster"], explain=True)
        finally:
            self.client.delete_model("slam-poster")
        self.assertEqual([o.name for o in plain.objects], ["slam-poster"])
        self.assertEqual(len(plain.objects[0].inliers_2d3d), 0)
        self.assertEqual(len(plain.objects[0].covariance), 0)
        self.assertEqual([o.name for o in full.objects], ["slam-poster"])
        detected = full.objects[0]
        self.assertEqual(len(detected.inliers_2d3d), detected.inliers)
        self.assertEqual(len(detected.covariance), 36)
        self.assertTrue(all(detected.covariance[i * 7] > 0 for i in range(6)))
        self.assertEqual(len(plain.explanations), 0)  # only when asked
        # Another corridor frame: the poster is not found, and the answer says where it dropped out.
        self.assertEqual(len(explained.objects), 0)
        self.assertEqual([e.name for e in explained.explanations], ["slam-poster"])
        self.assertNotIn(explained.explanations[0].outcome,
                         (object_pb2.OBJECT_OUTCOME_UNSPECIFIED, object_pb2.OBJECT_OUTCOME_DETECTED))

    def test_an_object_stream_tracks_unless_tracking_is_off(self):
        recog = os.environ.get("RECOG")
        if not recog:
            raise RuntimeError("set RECOG to the path of the recog binary")
        with tempfile.TemporaryDirectory(prefix="recog-python-test-") as tmp:
            model = Path(tmp) / "poster.robj"
            subprocess.run([recog, "model", "build", "--planar", str(corridor(1)), "--width",
                            "0.64", "--height", "0.48", "--name", "tracked-poster", "-o",
                            str(model)], check=True, capture_output=True)
            self.client.upload_model(model)
        try:
            camera = (500.0, 500.0, 256.0, 192.0)
            frames = [corridor(1)] * 3
            tracked = list(self.client.stream_objects(frames, camera, names=["tracked-poster"]))
            untracked = list(self.client.stream_objects(frames, camera, names=["tracked-poster"],
                                                        tracking=False))
        finally:
            self.client.delete_model("tracked-poster")
        self.assertEqual([[o.tracked for o in a.objects] for a in tracked],
                         [[False], [True], [True]])
        self.assertEqual([[o.tracked for o in a.objects] for a in untracked],
                         [[False], [False], [False]])

    def test_an_upload_passes_the_size_and_checksum_checks_before_the_file_is_refused(self):
        # Three chunks of bytes that are not a model: the server accepts the header's size and
        # SHA-256, then refuses the contents (a different message than a checksum mismatch).
        with self.assertRaises(InvalidArgument) as raised:
            self.client.upload_model(os.urandom(5 << 19), name="noise")
        self.assertNotIn("SHA-256", raised.exception.details)
        self.assertNotIn("bytes; the header said", raised.exception.details)
        self.assertEqual(list(self.client.list_models()), [])

    def test_an_upload_that_broke_off_is_resumed_from_the_bytes_the_server_kept(self):
        data = os.urandom(3 << 18)  # three 256 KiB chunks of bytes that are not a model
        request = repository_pb2.GetUploadStatusRequest(
            sha256=hashlib.sha256(data).hexdigest(), size_bytes=len(data))
        sent_first_chunk = threading.Event()
        cancelled = threading.Event()

        def first_chunk_then_wait():
            header = repository_pb2.PutModelHeader(sha256=request.sha256, size_bytes=len(data))
            yield repository_pb2.PutModelRequest(header=header)
            yield repository_pb2.PutModelRequest(chunk=data[:1 << 18])
            sent_first_chunk.set()
            cancelled.wait(timeout=60)  # the call stays open until the test cancels it

        stub = self.client._repository
        broken = stub.PutModel.future(first_chunk_then_wait(), timeout=60)
        self.assertTrue(sent_first_chunk.wait(timeout=10))
        # Nothing tells a client that the server has read a chunk of a call still open (it answers
        # at the end): the pause gives it time to, as a connection that breaks off later would.
        time.sleep(0.1)
        broken.cancel()
        cancelled.set()
        # The server keeps the bytes it had read once it sees the call end.
        held = wait_until(lambda: stub.GetUploadStatus(request, timeout=10).received_bytes,
                          "the server keeping the bytes of the cancelled upload")
        self.assertEqual(held, 1 << 18)
        # The client sends the rest only: the server has the whole file (size and SHA-256 pass)
        # and refuses its contents; the kept bytes were used.
        with self.assertRaises(InvalidArgument) as raised:
            self.client.upload_model(data, name="noise")
        self.assertNotIn("SHA-256", raised.exception.details)
        self.assertEqual(stub.GetUploadStatus(request, timeout=10).received_bytes, 0)

    def test_a_watch_ends_when_cancelled(self):
        # With the existing models (none has the prefix): the SYNCED event says that the watch is
        # established, and the consumer then waits for the next event.
        watch = self.client.watch_models("noise", include_existing=True)
        outcome = []
        synced = threading.Event()

        def consume():
            try:
                for event in watch:
                    outcome.append(event.change)
                    synced.set()
            except Cancelled as error:
                outcome.append(error.code)

        consumer = threading.Thread(target=consume)
        consumer.start()
        self.assertTrue(synced.wait(timeout=60), "the watch sent no SYNCED event")
        watch.cancel()
        consumer.join(timeout=10)
        self.assertFalse(consumer.is_alive())
        self.assertEqual(outcome, [repository_pb2.MODEL_CHANGE_SYNCED, grpc.StatusCode.CANCELLED])

    def test_a_watch_with_the_existing_models_says_when_it_has_sent_them(self):
        watch = self.client.watch_models("nothing-", include_existing=True)
        first = next(iter(watch))  # no model has this prefix: the state is empty
        watch.cancel()
        self.assertEqual(first.change, repository_pb2.MODEL_CHANGE_SYNCED)
        self.assertFalse(first.HasField("model"))

    def test_the_example_streams_a_folder(self):
        run = subprocess.run([sys.executable, str(EXAMPLE), "--server", self.target,
                              "--map", "example", str(CORRIDOR)],
                             capture_output=True, text=True, timeout=120, check=False)
        self.assertEqual(run.returncode, 0, run.stderr)
        self.assertEqual(run.stdout.splitlines()[-1],
                         "4 frames streamed into map 'example', 0 loops")
        self.assertEqual(self.client.get_map("example").frames, 4)


class SecuredServerTest(unittest.TestCase):
    """A recogd with TLS (tests/data/tls) and bearer tokens with read and write rights."""

    READER = "robot-token-0123456789"
    WRITER = "operator-token-0123456789"

    @classmethod
    def setUpClass(cls):
        """Writes the token file, starts recogd and waits until it serves."""
        tokens = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
        tokens.write("tokens:\n"
                     f"  - {{name: robot-7, token: \"{cls.READER}\", rights: [read]}}\n"
                     f"  - {{name: operator, token: \"{cls.WRITER}\", rights: [read, write]}}\n")
        tokens.close()
        cls.token_file = tokens.name
        cls.server = Recogd(args=["--tls-cert", str(TLS / "server.crt"), "--tls-key",
                                          str(TLS / "server.key"), "--token-file", tokens.name])
        try:
            cls.server.wait_until_serving(token=cls.READER, ca_file=TLS / "ca.crt")
        except BaseException:
            os.unlink(cls.token_file)
            raise

    @classmethod
    def tearDownClass(cls):
        """Stops recogd and checks that it exits with 0."""
        os.unlink(cls.token_file)
        cls.server.stop()

    def client(self, token: str | None, tls: bool = True) -> RecognitionClient:
        """A client of the server with ``token``, over TLS trusting the test CA or in plaintext."""
        client = RecognitionClient(self.server.target, token=token, tls=tls,
                                   ca_file=TLS / "ca.crt" if tls else None, deadline=5.0)
        self.addCleanup(client.close)
        return client

    def assert_raises(self, error: type, call, *args):
        """Checks that ``call(*args)`` raises ``error`` (a RecogError) with the server's message."""
        with self.assertRaises(error) as raised:
            call(*args)
        self.assertEqual(raised.exception.code, error.code)
        self.assertTrue(raised.exception.details)

    def test_the_write_token_creates_and_the_read_token_only_reads(self):
        writer = self.client(self.WRITER)
        self.assertEqual(writer.create_map("secured").name, "secured")
        reader = self.client(self.READER)
        self.assertIn("secured", [m.name for m in reader.list_maps()])
        self.assert_raises(PermissionDenied, reader.create_map, "other")
        self.assert_raises(PermissionDenied, reader.delete_map, "secured")
        self.assertEqual(writer.delete_map("secured"), 0)

    def test_the_environment_gives_the_server_the_token_file_and_the_ca(self):
        with tempfile.NamedTemporaryFile("w", suffix=".token") as token_file:
            token_file.write(f"  {self.WRITER}\n")
            token_file.flush()
            environment = {"RECOG_SERVER": self.server.target, "RECOG_TOKEN_FILE": token_file.name,
                           "RECOG_TLS_CA": str(TLS / "ca.crt")}
            with unittest.mock.patch.dict(os.environ, environment):
                client = RecognitionClient()
            self.addCleanup(client.close)
            self.assertEqual(client.target, self.server.target)
            self.assertEqual(client.create_map("from-environment").name, "from-environment")
            self.assertEqual(client.delete_map("from-environment"), 0)

    def test_calls_without_a_known_token_are_unauthenticated(self):
        self.assert_raises(Unauthenticated, self.client(None).get_map, "any")
        self.assert_raises(Unauthenticated,
                           self.client("unknown-token-0123456789").get_map, "any")

    def test_a_plaintext_client_cannot_talk_to_the_tls_server(self):
        self.assert_raises(Unavailable, self.client(self.WRITER, tls=False).get_map, "any")


class MutualTlsTest(unittest.TestCase):
    """A recogd that requires client certificates signed by the test CA."""

    @classmethod
    def setUpClass(cls):
        """Starts recogd and waits until it serves a client with the test certificate."""
        cls.server = Recogd(args=["--tls-cert", str(TLS / "server.crt"), "--tls-key",
                                  str(TLS / "server.key"), "--tls-client-ca", str(TLS / "ca.crt")])
        cls.server.wait_until_serving(ca_file=TLS / "ca.crt", cert_file=TLS / "client.crt",
                                      key_file=TLS / "client.key")

    @classmethod
    def tearDownClass(cls):
        """Stops recogd and checks that it exits with 0."""
        cls.server.stop()

    def test_a_client_certificate_from_the_environment_is_let_in_and_none_is_refused(self):
        environment = {"RECOG_SERVER": self.server.target, "RECOG_TLS_CA": str(TLS / "ca.crt"),
                       "RECOG_TLS_CERT": str(TLS / "client.crt"),
                       "RECOG_TLS_KEY": str(TLS / "client.key")}
        with unittest.mock.patch.dict(os.environ, environment):
            with RecognitionClient() as client:
                self.assertEqual(client.check_health(), "SERVING")
        with RecognitionClient(self.server.target, ca_file=TLS / "ca.crt", deadline=5.0,
                               retries=False) as anonymous:
            with self.assertRaises(Unavailable):
                anonymous.check_health()
        with self.assertRaises(InvalidArgument):
            RecognitionClient(self.server.target, cert_file=TLS / "client.crt")  # no key
        with self.assertRaises(NotFound):
            RecognitionClient(self.server.target, ca_file=TLS / "missing.crt")


if __name__ == "__main__":
    unittest.main(verbosity=2)
