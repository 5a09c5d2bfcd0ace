"""Tests of what recog_client puts on the channel, against an in-process fake server: gRPC's
service-config retries (UNAVAILABLE, RESOURCE_EXHAUSTED with ``grpc-retry-pushback-ms``; other
codes are final), the request ids of mutating calls (one per call, the same in every retry), the
headers (token from a file, map, shard), the exception classes, lazy pagers and the version.

The package must be on PYTHONPATH (ctest sets it); RECOG_VERSION, when set, is the version CMake
has. Exits with 77 (skipped) when Python's grpc or protobuf modules are missing.
"""

import hashlib
import os
import sys
import tempfile
import time
import unittest
import unittest.mock
import uuid
from concurrent import futures

try:
    import grpc
    import recog_client
    from recog_client import (DataLoss, InvalidArgument, NotFound, RecogError, RecognitionClient,
                              ResourceExhausted, Unavailable, place_pb2, repository_pb2)
    from recog_client._proto.recognition.v1 import place_pb2_grpc, repository_pb2_grpc
except ModuleNotFoundError as missing:
    if missing.name.split(".")[0] not in ("grpc", "google"):
        raise  # the package is not on PYTHONPATH: an error, not a skip
    print(f"SKIP: {missing} (Debian: apt-get install python3-grpcio python3-protobuf)",
          file=sys.stderr)
    sys.exit(77)

MAP_NAMES = [f"map-{i}" for i in range(5)]


class FakePlaces(place_pb2_grpc.PlaceRecognitionServicer):
    """Records every call (request, metadata) and fails some as their map names say."""

    def __init__(self):
        self.calls = []  # (method, request, metadata dict)
        self.failures_left = {}  # map name -> (code, failures still to give, trailing metadata)

    def record(self, method, request, context):
        """Records a call; aborts it when its map is set to fail."""
        self.calls.append((method, request, dict(context.invocation_metadata())))
        name = getattr(request, "name", "") or getattr(request, "map", "")
        code, left, trailers = self.failures_left.get(name, (None, 0, ()))
        if left > 0:
            self.failures_left[name] = (code, left - 1, trailers)
            context.set_trailing_metadata(trailers)
            context.abort(code, f"{name} fails")

    def attempts(self, method):
        """The calls of ``method`` seen so far."""
        return [call for call in self.calls if call[0] == method]

    def CreateMap(self, request, context):
        self.record("CreateMap", request, context)
        return place_pb2.CreateMapResponse(map=place_pb2.MapInfo(name=request.name))

    def GetMap(self, request, context):
        self.record("GetMap", request, context)
        return place_pb2.GetMapResponse(map=place_pb2.MapInfo(name=request.name))

    def ListMaps(self, request, context):
        self.record("ListMaps", request, context)
        start = int(request.page_token or 0)
        end = start + request.page_size
        return place_pb2.ListMapsResponse(
            maps=[place_pb2.MapInfo(name=n) for n in MAP_NAMES[start:end]],
            next_page_token=str(end) if end < len(MAP_NAMES) else "")

    def DeleteMap(self, request, context):
        self.record("DeleteMap", request, context)
        return place_pb2.DeleteMapResponse(frames_deleted=7)

    def AddFrame(self, request, context):
        self.record("AddFrame", request, context)
        return place_pb2.AddFrameResponse(frame_id=3)

    def QueryPlace(self, request, context):
        self.record("QueryPlace", request, context)
        return place_pb2.QueryPlaceResponse()

    def RemoveFrame(self, request, context):
        self.record("RemoveFrame", request, context)
        return place_pb2.RemoveFrameResponse(removed_frame_ids=[request.frame_id])


class FakeRepository(repository_pb2_grpc.ObjectRepositoryServicer):
    """Records the request ids of model uploads and deletions."""

    def __init__(self):
        self.request_ids = []

    def GetUploadStatus(self, request, context):
        return repository_pb2.GetUploadStatusResponse(received_bytes=0)

    def PutModel(self, request_iterator, context):
        header = next(request_iterator).header
        size = sum(len(r.chunk) for r in request_iterator)
        self.request_ids.append(header.request_id)
        return repository_pb2.PutModelResponse(
            model=repository_pb2.ModelInfo(name=header.name, size_bytes=size))

    def GetModel(self, request, context):
        """A download whose bytes do not match the SHA-256 announced first."""
        yield repository_pb2.GetModelResponse(info=repository_pb2.ModelInfo(
            name=request.name, version=1, size_bytes=3, sha256=hashlib.sha256(b"abc").hexdigest()))
        yield repository_pb2.GetModelResponse(chunk=b"abd")

    def DeleteModel(self, request, context):
        self.request_ids.append(request.request_id)
        return repository_pb2.DeleteModelResponse(versions_deleted=1)


class ChannelTest(unittest.TestCase):
    """One fake server for the class; a client that reads its token from RECOG_TOKEN_FILE."""

    @classmethod
    def setUpClass(cls):
        """Starts the fake server on a free loopback port."""
        cls.places = FakePlaces()
        cls.repository = FakeRepository()
        cls.server = grpc.server(futures.ThreadPoolExecutor(max_workers=4))
        place_pb2_grpc.add_PlaceRecognitionServicer_to_server(cls.places, cls.server)
        repository_pb2_grpc.add_ObjectRepositoryServicer_to_server(cls.repository, cls.server)
        cls.target = f"127.0.0.1:{cls.server.add_insecure_port('127.0.0.1:0')}"
        cls.server.start()
        cls.token_file = tempfile.NamedTemporaryFile("w", suffix=".token", delete=False)
        cls.token_file.write("\n  robot-token-0123456789 \n")
        cls.token_file.close()
        environment = {"RECOG_SERVER": cls.target, "RECOG_TOKEN_FILE": cls.token_file.name}
        with unittest.mock.patch.dict(os.environ, environment):
            cls.client = RecognitionClient(shard="shard_a")

    @classmethod
    def tearDownClass(cls):
        """Stops the server."""
        cls.client.close()
        cls.server.stop(None)
        os.unlink(cls.token_file.name)

    def fail(self, name: str, code: grpc.StatusCode, times: int, trailers=()):
        """Makes the next ``times`` calls about map ``name`` fail with ``code``."""
        self.places.failures_left[name] = (code, times, trailers)

    def test_unavailable_is_retried_with_the_same_request_id_and_headers(self):
        self.fail("flaky", grpc.StatusCode.UNAVAILABLE, 2)
        self.assertEqual(self.client.create_map("flaky").name, "flaky")
        attempts = [c for c in self.places.attempts("CreateMap") if c[1].name == "flaky"]
        self.assertEqual(len(attempts), 3)
        request_ids = {request.request_id for _, request, _ in attempts}
        self.assertEqual(len(request_ids), 1)
        self.assertEqual(uuid.UUID(request_ids.pop()).version, 4)
        metadata = attempts[-1][2]
        self.assertEqual(metadata["authorization"], "Bearer robot-token-0123456789")
        self.assertEqual(metadata["x-recog-map"], "flaky")
        self.assertEqual(metadata["x-recog-shard"], "shard_a")

    def test_a_busy_server_is_retried_after_its_pushback(self):
        self.fail("busy", grpc.StatusCode.RESOURCE_EXHAUSTED, 1,
                  (("grpc-retry-pushback-ms", "400"),))
        start = time.monotonic()
        self.assertEqual(self.client.get_map("busy").name, "busy")
        self.assertGreaterEqual(time.monotonic() - start, 0.4)  # not the policy's 0.1 s backoff
        self.assertEqual(len([c for c in self.places.attempts("GetMap")
                              if c[1].name == "busy"]), 2)

    def test_retries_stop_after_five_attempts_and_raise_the_typed_error(self):
        self.fail("always-busy", grpc.StatusCode.RESOURCE_EXHAUSTED, 100)
        with self.assertRaises(ResourceExhausted) as raised:
            self.client.get_map("always-busy")
        self.assertIsInstance(raised.exception, RecogError)
        self.assertEqual(raised.exception.details, "always-busy fails")
        self.assertEqual(len([c for c in self.places.attempts("GetMap")
                              if c[1].name == "always-busy"]), 5)

    def test_other_codes_are_final(self):
        for name, code, error in (("gone", grpc.StatusCode.NOT_FOUND, NotFound),
                                  ("corrupt", grpc.StatusCode.DATA_LOSS, DataLoss),
                                  ("bad", grpc.StatusCode.INVALID_ARGUMENT, InvalidArgument)):
            self.fail(name, code, 100)
            with self.assertRaises(error) as raised:
                self.client.get_map(name)
            self.assertEqual(raised.exception.code, code)
            self.assertEqual(len([c for c in self.places.attempts("GetMap")
                                  if c[1].name == name]), 1)
        self.assertTrue(issubclass(InvalidArgument, ValueError))

    def test_every_mutating_call_sends_a_request_id_and_a_given_one_is_kept(self):
        self.client.delete_map("m", request_id="delete-1")
        self.client.add_frame("m", b"jpeg")
        self.client.query_place("m", b"jpeg")
        self.client.remove_frame("m", frame_id=3)
        sent = {method: request.request_id for method, request, _ in self.places.calls
                if getattr(request, "map", "") == "m" or getattr(request, "name", "") == "m"}
        self.assertEqual(sent["DeleteMap"], "delete-1")
        for method in ("AddFrame", "QueryPlace", "RemoveFrame"):
            self.assertEqual(uuid.UUID(sent[method]).version, 4, method)
        self.assertEqual(len(set(sent.values())), 4)
        self.client.upload_model(b"model bytes", name="m", request_id="upload-1")
        self.client.delete_model("m")
        self.assertEqual(self.repository.request_ids[-2], "upload-1")
        self.assertEqual(uuid.UUID(self.repository.request_ids[-1]).version, 4)

    def test_a_download_that_does_not_match_its_checksum_is_data_loss(self):
        with self.assertRaises(DataLoss) as raised:
            self.client.download_model("m")
        self.assertIn("SHA-256", raised.exception.details)

    def test_listings_fetch_pages_as_they_are_read(self):
        before = len(self.places.attempts("ListMaps"))
        maps = self.client.list_maps(page_size=2)
        self.assertEqual(len(self.places.attempts("ListMaps")), before)  # nothing fetched yet
        self.assertEqual(next(maps).name, "map-0")
        self.assertEqual(len(self.places.attempts("ListMaps")), before + 1)
        self.assertEqual([m.name for m in maps], MAP_NAMES[1:])
        self.assertEqual(len(self.places.attempts("ListMaps")), before + 3)

    def test_retries_can_be_turned_off(self):
        self.fail("once", grpc.StatusCode.UNAVAILABLE, 1)
        with RecognitionClient(self.target, retries=False) as single:
            with self.assertRaises(Unavailable):
                single.get_map("once")

    def test_bad_options_are_refused_before_connecting(self):
        with self.assertRaises(InvalidArgument):
            RecognitionClient(self.target, token="a", token_file=self.token_file.name)
        with self.assertRaises(InvalidArgument):
            RecognitionClient(self.target, shard="shard-a")
        with self.assertRaises(InvalidArgument):
            RecognitionClient(self.target, token="two words")
        with self.assertRaises(NotFound):
            RecognitionClient(self.target, token_file="/nonexistent/token")

    def test_the_version_is_the_projects_and_the_retry_policy_is_shipped(self):
        self.assertRegex(recog_client.__version__, r"^\d+\.\d+\.\d+$")
        if os.environ.get("RECOG_VERSION"):
            self.assertEqual(recog_client.__version__, os.environ["RECOG_VERSION"])
        self.assertIn('"retryPolicy"', recog_client.service_config())


if __name__ == "__main__":
    unittest.main(verbosity=2)
