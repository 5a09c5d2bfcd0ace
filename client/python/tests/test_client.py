"""Tests of the Python client against the real recogd.

The server binary is taken from the environment variable RECOGD, the CLI (to build a model) from
RECOG and the corridor images from RECOG_SOURCE_DIR/tests/data/corridor; the generated stubs and recognition_client.py must be on
PYTHONPATH (ctest sets all three: ``ctest -R python``). Exits with 77 (skipped) when Python's
grpc or protobuf modules are missing.
"""

import hashlib
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import unittest
import zlib
from pathlib import Path
from typing import Sequence

try:
    import grpc
    from recognition.v1 import place_pb2, repository_pb2
    from recognition_client import RecognitionClient, make_frame
except ModuleNotFoundError as missing:
    if missing.name.split(".")[0] not in ("grpc", "google"):
        raise  # the stubs or the client are not on PYTHONPATH: an error, not a skip
    print(f"SKIP: {missing} (Debian: apt-get install python3-grpcio python3-protobuf)",
          file=sys.stderr)
    sys.exit(77)

CORRIDOR = Path(os.environ.get("RECOG_SOURCE_DIR", ".")) / "tests" / "data" / "corridor"
TLS = Path(os.environ.get("RECOG_SOURCE_DIR", ".")) / "tests" / "data" / "tls"
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "stream_folder.py"
STARTUP_SECONDS = 30
SHUTDOWN_SECONDS = 30


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


def free_port() -> int:
    """A free loopback port (bound, read, released: another process may take it, rarely)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Recogd:
    """A recogd process on a free loopback port with a fresh data directory and ``args``."""

    def __init__(self, args: Sequence[str] = ()):
        recogd = os.environ.get("RECOGD")
        if not recogd:
            raise RuntimeError("set RECOGD to the path of the recogd binary")
        self.data_dir = tempfile.TemporaryDirectory(prefix="recog-python-test-")
        self.target = f"127.0.0.1:{free_port()}"  # the test certificate names 127.0.0.1
        self.process = subprocess.Popen([recogd, "--listen", self.target, "--data-dir",
                                         self.data_dir.name, "--metrics-listen", "",
                                         "--log-level", "warn", *args])

    def wait_until_serving(self, **client_options) -> None:
        """Polls list_maps until it stops answering UNAVAILABLE (at most STARTUP_SECONDS), each
        time from a new client with ``client_options`` (a channel that failed to connect waits
        out a growing backoff); stops the server and raises when it does not come up."""
        deadline = time.monotonic() + STARTUP_SECONDS
        try:
            while True:
                if self.process.poll() is not None:
                    raise RuntimeError(f"recogd exited with {self.process.returncode} at start-up")
                try:
                    with RecognitionClient(self.target, **client_options) as probe:
                        probe.list_maps()
                    return
                except grpc.RpcError as error:
                    if error.code() != grpc.StatusCode.UNAVAILABLE or time.monotonic() > deadline:
                        raise
                time.sleep(0.1)
        except BaseException:
            self.process.kill()
            self.process.wait()
            self.data_dir.cleanup()
            raise

    def stop(self) -> None:
        """Stops recogd with SIGTERM and checks that it exits with 0."""
        self.process.send_signal(signal.SIGTERM)
        try:
            code = self.process.wait(timeout=SHUTDOWN_SECONDS)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise AssertionError(f"recogd did not stop within {SHUTDOWN_SECONDS} s of SIGTERM")
        finally:
            self.data_dir.cleanup()
        if code != 0:
            raise AssertionError(f"recogd exited with {code} after SIGTERM")


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

    def assert_code(self, code: grpc.StatusCode, call, *args):
        """Checks that ``call(*args)`` raises grpc.RpcError with ``code``."""
        with self.assertRaises(grpc.RpcError) as raised:
            call(*args)
        self.assertEqual(raised.exception.code(), code, raised.exception.details())

    def test_map_lifecycle(self):
        info = self.client.create_map("lifecycle", {"temporal_matches": 2})
        self.assertEqual(info.name, "lifecycle")
        self.assertEqual(info.settings.temporal_matches, 2)
        self.assertEqual(info.frames, 0)
        self.assert_code(grpc.StatusCode.ALREADY_EXISTS, self.client.create_map, "lifecycle")
        self.assertIn("lifecycle", [m.name for m in self.client.list_maps()])
        self.assertEqual(self.client.get_map("lifecycle").id, info.id)
        self.assertEqual(self.client.delete_map("lifecycle"), 0)
        self.assert_code(grpc.StatusCode.NOT_FOUND, self.client.get_map, "lifecycle")
        self.assert_code(grpc.StatusCode.NOT_FOUND, self.client.delete_map, "lifecycle")

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
        self.assertFalse(response.result.HasField("frame_id"))  # nothing was added
        self.assertEqual(self.client.get_map("hall").frames, 4)

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
            with self.assertRaises(grpc.RpcError) as refused:
                self.client.add_frame("rgbd", frame)
            self.assertEqual(refused.exception.code(), grpc.StatusCode.INVALID_ARGUMENT)
            self.assertIn(words, refused.exception.details())
        with self.assertRaises(ValueError):
            make_frame(corridor(20), intrinsics=k, right=corridor(60))  # no baseline
        with self.assertRaises(ValueError):
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
        self.assert_code(grpc.StatusCode.INVALID_ARGUMENT, self.client.query_place, "slam",
                         corridor(41).read_bytes(), False, {"top_k": 51})

        self.assertEqual(self.client.remove_frame("slam", frame_id=2), [2])
        self.assertEqual(self.client.remove_frame("slam", client_frame_id="kf-60"), [3])
        self.assert_code(grpc.StatusCode.NOT_FOUND, self.client.remove_frame, "slam", 2)
        self.assert_code(grpc.StatusCode.NOT_FOUND, self.client.remove_frame, "nowhere", 0)
        with self.assertRaises(ValueError):
            self.client.remove_frame("slam")
        result = self.client.query_place("slam", corridor(41).read_bytes(),
                                         result_options={"top_k": 50}).result
        self.assertNotEqual(result.match_frame_id, 2)
        self.assertTrue(all(c.frame_id < 2 for c in result.candidates), result.candidates)
        self.assertEqual(self.client.get_map("slam").frames, 2)

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
        self.assertEqual(self.client.list_models(), [])
        response = self.client.recognize_objects(corridor(1), (500.0, 500.0, 320.0, 240.0))
        self.assertEqual(len(response.objects), 0)
        self.assert_code(grpc.StatusCode.NOT_FOUND, self.client.download_model, "nothing")
        self.assert_code(grpc.StatusCode.NOT_FOUND, self.client.delete_model, "nothing")

    def test_objects_carry_inliers_and_covariance_when_asked(self):
        recog = os.environ.get("RECOG")
        if not recog:
            raise RuntimeError("set RECOG to the path of the recog binary")
        with tempfile.TemporaryDirectory(prefix="recog-python-test-") as tmp:
            model = Path(tmp) / "poster.robj"
            subprocess.run([recog, "model", "build", "--planar", str(corridor(1)), "--width",
                            "0.64", "--height", "0.48", "--name", "slam-poster", "-o",
                            str(model)], check=True, capture_output=True)
            self.client.upload_model(model)
        try:
            camera = (500.0, 500.0, 256.0, 192.0)
            plain = self.client.recognize_objects(corridor(1), camera, names=["slam-poster"])
            full = self.client.recognize_objects(corridor(1), camera, names=["slam-poster"],
                                                 include_inliers=True, include_covariance=True)
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
        with self.assertRaises(grpc.RpcError) as raised:
            self.client.upload_model(os.urandom(5 << 19), name="noise")
        self.assertEqual(raised.exception.code(), grpc.StatusCode.INVALID_ARGUMENT)
        self.assertNotIn("SHA-256", raised.exception.details())
        self.assertNotIn("bytes; the header said", raised.exception.details())
        self.assertEqual(self.client.list_models(), [])

    def test_an_upload_that_broke_off_is_resumed_from_the_bytes_the_server_kept(self):
        data = os.urandom(3 << 18)  # three 256 KiB chunks of bytes that are not a model
        request = repository_pb2.GetUploadStatusRequest(
            sha256=hashlib.sha256(data).hexdigest(), size_bytes=len(data))
        sent_first_chunk = threading.Event()

        def first_chunk_then_wait():
            header = repository_pb2.PutModelHeader(sha256=request.sha256, size_bytes=len(data))
            yield repository_pb2.PutModelRequest(header=header)
            yield repository_pb2.PutModelRequest(chunk=data[:1 << 18])
            sent_first_chunk.set()
            time.sleep(30)  # until the call is cancelled

        stub = self.client._repository
        broken = stub.PutModel.future(first_chunk_then_wait(), timeout=60)
        self.assertTrue(sent_first_chunk.wait(timeout=10))
        held = 0
        for _ in range(50):  # the server keeps the bytes once it sees the call end
            time.sleep(0.1)
            if held == 0 and not broken.done():
                broken.cancel()
            held = stub.GetUploadStatus(request, timeout=10).received_bytes
            if held > 0:
                break
        self.assertEqual(held, 1 << 18)
        # The client sends the rest only: the server has the whole file (size and SHA-256 pass)
        # and refuses its contents; the kept bytes were used.
        with self.assertRaises(grpc.RpcError) as raised:
            self.client.upload_model(data, name="noise")
        self.assertEqual(raised.exception.code(), grpc.StatusCode.INVALID_ARGUMENT)
        self.assertNotIn("SHA-256", raised.exception.details())
        self.assertEqual(stub.GetUploadStatus(request, timeout=10).received_bytes, 0)

    def test_a_watch_ends_when_cancelled(self):
        watch = self.client.watch_models("noise")
        outcome = []

        def consume():
            try:
                outcome.extend(watch)
            except grpc.RpcError as error:
                outcome.append(error.code())

        consumer = threading.Thread(target=consume)
        consumer.start()
        time.sleep(0.5)  # the watch is established and waiting
        watch.cancel()
        consumer.join(timeout=10)
        self.assertFalse(consumer.is_alive())
        self.assertEqual(outcome, [grpc.StatusCode.CANCELLED])

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
        self.assertIn("streamed 4 images into map 'example'", run.stdout)
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
        cls.ca = (TLS / "ca.crt").read_bytes()
        cls.server = Recogd(args=["--tls-cert", str(TLS / "server.crt"), "--tls-key",
                                          str(TLS / "server.key"), "--token-file", tokens.name])
        try:
            cls.server.wait_until_serving(token=cls.READER, root_certificates=cls.ca)
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
        client = RecognitionClient(self.server.target, token=token,
                                   root_certificates=self.ca if tls else None, timeout=5.0)
        self.addCleanup(client.close)
        return client

    def assert_code(self, code: grpc.StatusCode, call, *args):
        """Checks that ``call(*args)`` raises grpc.RpcError with ``code``."""
        with self.assertRaises(grpc.RpcError) as raised:
            call(*args)
        self.assertEqual(raised.exception.code(), code, raised.exception.details())

    def test_the_write_token_creates_and_the_read_token_only_reads(self):
        writer = self.client(self.WRITER)
        self.assertEqual(writer.create_map("secured").name, "secured")
        reader = self.client(self.READER)
        self.assertIn("secured", [m.name for m in reader.list_maps()])
        self.assert_code(grpc.StatusCode.PERMISSION_DENIED, reader.create_map, "other")
        self.assert_code(grpc.StatusCode.PERMISSION_DENIED, reader.delete_map, "secured")
        self.assertEqual(writer.delete_map("secured"), 0)

    def test_calls_without_a_known_token_are_unauthenticated(self):
        self.assert_code(grpc.StatusCode.UNAUTHENTICATED, self.client(None).list_maps)
        self.assert_code(grpc.StatusCode.UNAUTHENTICATED,
                         self.client("unknown-token-0123456789").list_maps)

    def test_a_plaintext_client_cannot_talk_to_the_tls_server(self):
        self.assert_code(grpc.StatusCode.UNAVAILABLE, self.client(self.WRITER, tls=False).list_maps)

if __name__ == "__main__":
    unittest.main(verbosity=2)
