"""RecognitionClient: one connection to recogd and a method per call of its API
(``recognition.v1``): place maps, frames and place queries, object recognition, the model
repository, health and online checkpoints. Results are the generated protobuf messages
(``recog_client.place_pb2``, ..., documented in ``proto/recognition/v1/*.proto``).

What every call gets, as in the C++ client (client/cpp/client_options.h):
- a deadline: ``deadline`` (10 s) for unary calls and listings, ``transfer_deadline`` (10 min)
  for model uploads, downloads and checkpoints; streams last until their caller ends them;
- the bearer token (``authorization: Bearer <token>``), the routing headers of a router of shards
  (``x-recog-map`` on every call about a map, ``x-recog-shard`` when ``shard`` is set);
- retries by gRPC itself, with the one policy of all clients (``proto/service_config.json``,
  shipped in this package): UNAVAILABLE and RESOURCE_EXHAUSTED, 5 attempts, exponential backoff
  from 0.1 s to 5 s, honouring the server's ``grpc-retry-pushback-ms``;
- on every call that changes the server (CreateMap, DeleteMap, AddFrame, QueryPlace, RemoveFrame,
  PutModel, DeleteModel), a ``request_id`` (a fresh UUID unless the caller gives one): a retry
  carries the same id, so a server that already applied it answers with the stored result;
- errors raised as :mod:`recog_client.errors` classes (``NotFound``, ``Unavailable``, ...), never
  as ``grpc.RpcError``.

Defaults from the environment when an argument is not given: ``RECOG_SERVER`` (the target),
``RECOG_TOKEN_FILE`` (a file holding the bearer token), ``RECOG_TLS_CA`` (PEM of the CA to trust;
turns TLS on), ``RECOG_TLS_CERT`` and ``RECOG_TLS_KEY`` (this client's certificate and key, for
mutual TLS; turn TLS on).

Example::

    with RecognitionClient("127.0.0.1:50051") as client:
        client.create_map("lab", {"temporal_matches": 3})
        for answer in client.stream_frames("lab", ["1.jpg", "2.jpg"]):
            print(answer.sequence, answer.result.status)
"""

import hashlib
import importlib.resources
import os
import re
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Generic, TypeVar

import grpc

from ._proto.grpc.health.v1 import health_pb2, health_pb2_grpc
from ._proto.recognition.v1 import (admin_pb2, admin_pb2_grpc, common_pb2, object_pb2,
                                    object_pb2_grpc, place_pb2, place_pb2_grpc, repository_pb2,
                                    repository_pb2_grpc)
from .errors import AlreadyExists, DataLoss, InvalidArgument, NotFound, from_rpc_error
from .frames import Image, as_frame, make_intrinsics, read_bytes

#: The server's address when neither the argument nor RECOG_SERVER gives one.
DEFAULT_TARGET = "127.0.0.1:50051"
#: The metadata header that names a call's place map for a router of shards (wire/routing.h).
MAP_HEADER = "x-recog-map"
#: The metadata header that names the shard of calls without a map (wire/routing.h).
SHARD_HEADER = "x-recog-shard"
#: Size of the chunks :meth:`RecognitionClient.upload_model` sends (as the C++ client).
UPLOAD_CHUNK_BYTES = 256 << 10

T = TypeVar("T")


def service_config() -> str:
    """The JSON of the clients' retry policy (proto/service_config.json, shipped here)."""
    return importlib.resources.files(__package__).joinpath("service_config.json").read_text()


def _result_options(options: place_pb2.ResultOptions | Mapping | None) -> place_pb2.ResultOptions:
    """Result options given as a message, a mapping of its fields (``top_k``,
    ``include_correspondences``, ``include_fundamental``, ``include_relative_pose``), or None."""
    if isinstance(options, place_pb2.ResultOptions):
        return options
    return place_pb2.ResultOptions(**(options or {}))


def _map_settings(settings: place_pb2.MapSettings | Mapping | None) -> place_pb2.MapSettings:
    """Map settings given as a message, a mapping of its fields, or None (defaults)."""
    if isinstance(settings, place_pb2.MapSettings):
        return settings
    return place_pb2.MapSettings(**(settings or {}))


def _request_id(given: str | None) -> str:
    """The caller's request id, or a fresh UUID."""
    return given if given is not None else str(uuid.uuid4())


def _read_config_file(path: str, what: str) -> bytes:
    """The contents of a TLS or token file; NotFound when it cannot be read."""
    try:
        return Path(path).read_bytes()
    except OSError as error:
        raise NotFound(f"cannot read the {what} {path}: {error.strerror}") from error


def _open_next_file(directory: Path, files: list) -> tuple | None:
    """Opens the next file of a checkpoint with bytes to come, as (file, size), after creating
    the empty ones before it; None when no file is left. Pops the files it handles."""
    while files:
        entry = files.pop(0)
        file = open(directory / Path(entry.name).name, "wb")
        if entry.size_bytes > 0:
            return file, entry.size_bytes
        _sync_and_close(file)
    return None


def _sync_and_close(file) -> None:
    """Flushes a written file to the disk and closes it."""
    file.flush()
    os.fsync(file.fileno())
    file.close()


class Stream(Generic[T]):
    """The answers of a streaming call, in order: iterate it; ``cancel()`` (from any thread) ends
    the call. An error of the whole call is raised during the iteration as a RecogError; an
    exception raised by the caller's iterator of frames is raised as itself. A context manager
    that cancels the call on exit."""

    def __init__(self, call, source_failures: list[BaseException]):
        """Wraps a gRPC call; ``source_failures`` collects the request iterator's exception."""
        self._call = call
        self._source_failures = source_failures

    def __iter__(self) -> "Stream[T]":
        """The stream itself."""
        return self

    def __next__(self) -> T:
        """The next answer; StopIteration when the server ended the stream."""
        try:
            return next(self._call)
        except grpc.RpcError as error:
            if self._source_failures:
                raise self._source_failures[0] from None
            raise from_rpc_error(error) from error

    def cancel(self) -> None:
        """Ends the call; a pending or later iteration raises ``Cancelled``."""
        self._call.cancel()

    def __enter__(self) -> "Stream[T]":
        """The stream itself."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Cancels the call."""
        self.cancel()


def _guarded(requests: Iterator, failures: list[BaseException]) -> Iterator:
    """Yields ``requests``, keeping the exception that ends them (gRPC only reports UNKNOWN)."""
    try:
        yield from requests
    except Exception as error:
        failures.append(error)
        raise


class RecognitionClient:
    """A connection to recogd (thread-safe: share one per process). See the module comment.

    Arguments (all optional; the environment variables of the module comment fill the gaps):
        target: the server's address as gRPC takes it (``host:port``, ``dns:///host:port``,
            ``unix:path``); RECOG_SERVER, else 127.0.0.1:50051.
        token: the bearer token; or token_file: a file holding it (whitespace around it is
            ignored; RECOG_TOKEN_FILE). Not both.
        tls: True for TLS, False for plaintext; None (default): TLS when any of ca_file, cert_file,
            key_file is given.
        ca_file: PEM of the CA(s) that signed the server's certificate (RECOG_TLS_CA); None with
            TLS: the system's trust store.
        cert_file, key_file: this client's certificate chain and key for mutual TLS
            (RECOG_TLS_CERT, RECOG_TLS_KEY); both or neither.
        deadline: seconds of every unary call and listing page (10).
        transfer_deadline: seconds of a model upload or download or a checkpoint (600).
        shard: behind a router of shards, the shard that calls without a map go to
            (``x-recog-shard``); 1 to 64 characters of [A-Za-z0-9_].
        retries: False turns gRPC's retries off (every call is tried once).
        max_message_bytes: the largest message sent or received (32 MiB, the server's default).

    Raises InvalidArgument for bad arguments and NotFound for a TLS or token file that cannot be
    read. The channel connects lazily, at the first call.
    """

    def __init__(self, target: str | None = None, *, token: str | None = None,
                 token_file: str | os.PathLike | None = None, tls: bool | None = None,
                 ca_file: str | os.PathLike | None = None,
                 cert_file: str | os.PathLike | None = None,
                 key_file: str | os.PathLike | None = None, deadline: float = 10.0,
                 transfer_deadline: float = 600.0, shard: str = "", retries: bool = True,
                 max_message_bytes: int = 32 << 20):
        """Checks the arguments, reads the files and opens the channel."""
        environ = os.environ
        self.target = target or environ.get("RECOG_SERVER") or DEFAULT_TARGET
        if token is not None and token_file is not None:
            raise InvalidArgument("give token or token_file, not both")
        if token is None:
            token_file = token_file or environ.get("RECOG_TOKEN_FILE") or None
            if token_file is not None:
                token = _read_config_file(token_file, "token file").decode("utf-8", "replace")
                token = token.strip()
                if not token:
                    raise InvalidArgument(f"the token file {token_file} is empty")
        if token is not None and not re.fullmatch(r"[\x21-\x7e]+", token):
            raise InvalidArgument("a token is one or more visible ASCII characters")
        if shard and not re.fullmatch(r"[A-Za-z0-9_]{1,64}", shard):
            raise InvalidArgument("shard must have at most 64 characters of [A-Za-z0-9_]")
        if not (deadline > 0 and transfer_deadline > 0):
            raise InvalidArgument("deadlines are positive seconds")
        self.deadline = deadline
        self.transfer_deadline = transfer_deadline

        ca_file = ca_file or environ.get("RECOG_TLS_CA") or None
        cert_file = cert_file or environ.get("RECOG_TLS_CERT") or None
        key_file = key_file or environ.get("RECOG_TLS_KEY") or None
        if (cert_file is None) != (key_file is None):
            raise InvalidArgument("cert_file and key_file go together (mutual TLS)")
        if tls is None:
            tls = any(f is not None for f in (ca_file, cert_file, key_file))
        options = [("grpc.max_send_message_length", max_message_bytes),
                   ("grpc.max_receive_message_length", max_message_bytes),
                   ("grpc.enable_retries", int(retries)),
                   # Reconnect at the pace of the retry policy (as the C++ client).
                   ("grpc.initial_reconnect_backoff_ms", 100),
                   ("grpc.max_reconnect_backoff_ms", 5000)]
        if retries:
            options.append(("grpc.service_config", service_config()))
        if tls:
            credentials = grpc.ssl_channel_credentials(
                root_certificates=_read_config_file(ca_file, "CA file") if ca_file else None,
                private_key=_read_config_file(key_file, "key file") if key_file else None,
                certificate_chain=_read_config_file(cert_file, "certificate file")
                if cert_file else None)
            self._channel = grpc.secure_channel(self.target, credentials, options)
        else:
            self._channel = grpc.insecure_channel(self.target, options)
        self._metadata: tuple = ()
        if token is not None:
            self._metadata += (("authorization", f"Bearer {token}"),)
        if shard:
            self._metadata += ((SHARD_HEADER, shard),)
        self._places = place_pb2_grpc.PlaceRecognitionStub(self._channel)
        self._objects = object_pb2_grpc.ObjectRecognitionStub(self._channel)
        self._repository = repository_pb2_grpc.ObjectRepositoryStub(self._channel)
        self._admin = admin_pb2_grpc.AdminStub(self._channel)
        self._health = health_pb2_grpc.HealthStub(self._channel)

    def close(self) -> None:
        """Closes the channel; calls in progress are cancelled."""
        self._channel.close()

    def __enter__(self) -> "RecognitionClient":
        """Returns the client itself."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Closes the client."""
        self.close()

    def _with_map(self, map_name: str | None) -> tuple:
        """The call metadata: credentials, shard, and the routing header of a call about a map."""
        return self._metadata + ((MAP_HEADER, map_name),) if map_name else self._metadata

    def _unary(self, method, request, map_name: str | None = None,
               deadline: float | None = None):
        """Runs a unary (or client-streaming) call; RecogError for a failure."""
        try:
            return method(request, timeout=deadline or self.deadline,
                          metadata=self._with_map(map_name))
        except grpc.RpcError as error:
            raise from_rpc_error(error) from error

    def _stream(self, method, requests, map_name: str | None = None,
                deadline: float | None = None) -> Stream:
        """Starts a server-streaming call (``requests`` a message, or an iterator of them)."""
        failures: list[BaseException] = []
        if isinstance(requests, Iterator):
            requests = _guarded(requests, failures)
        call = method(requests, timeout=deadline, metadata=self._with_map(map_name))
        return Stream(call, failures)

    def _pages(self, method, request, field: str) -> Iterator:
        """The items of ``field`` of a paged listing, fetched a page at a time as they are read."""
        while True:
            response = self._unary(method, request)
            yield from getattr(response, field)
            if not response.next_page_token:
                return
            request.page_token = response.next_page_token

    # Place recognition.

    def create_map(self, name: str, settings: place_pb2.MapSettings | Mapping | None = None, *,
                   request_id: str | None = None) -> place_pb2.MapInfo:
        """Creates an empty map and returns its description.

        ``settings`` is a ``MapSettings``, a mapping of its fields (e.g.
        ``{"temporal_matches": 0, "recent_frames": 1}``) or None; unset fields take the server's
        defaults. ``AlreadyExists`` when the name is taken.
        """
        request = place_pb2.CreateMapRequest(name=name, settings=_map_settings(settings),
                                             request_id=_request_id(request_id))
        return self._unary(self._places.CreateMap, request, name).map

    def get_map(self, name: str) -> place_pb2.MapInfo:
        """Returns the description of a map (``NotFound`` when there is none)."""
        return self._unary(self._places.GetMap, place_pb2.GetMapRequest(name=name), name).map

    def list_maps(self, page_size: int = 0) -> Iterator[place_pb2.MapInfo]:
        """Every map, by name, read lazily a page at a time (``page_size`` 0: the server's, 100).
        ``list(client.list_maps())`` for all of them."""
        return self._pages(self._places.ListMaps, place_pb2.ListMapsRequest(page_size=page_size),
                           "maps")

    def delete_map(self, name: str, *, request_id: str | None = None) -> int:
        """Deletes a map and its frames; returns how many frames it had. ``NotFound``."""
        request = place_pb2.DeleteMapRequest(name=name, request_id=_request_id(request_id))
        return self._unary(self._places.DeleteMap, request, name).frames_deleted

    def add_frame(self, map_name: str, image: Image, timestamp: float | None = None,
                  client_frame_id: str = "", *, request_id: str | None = None
                  ) -> place_pb2.AddFrameResponse:
        """Adds a frame to a map without querying it; the response carries its ``frame_id``.

        ``image`` in any form of :mod:`recog_client.frames`; ``timestamp`` (seconds, None =
        unknown, 0.0 is a time)
        and ``client_frame_id`` (the client's own id of the frame, e.g. a SLAM keyframe id: the
        map keeps it and returns it whenever the frame is a match) apply when ``image`` is not
        already a Frame.
        """
        request = place_pb2.AddFrameRequest(map=map_name,
                                            frame=as_frame(image, timestamp, client_frame_id),
                                            request_id=_request_id(request_id))
        return self._unary(self._places.AddFrame, request, map_name)

    def query_place(self, map_name: str, image: Image, add_frame: bool = False,
                    result_options: place_pb2.ResultOptions | Mapping | None = None,
                    client_frame_id: str = "", *, request_id: str | None = None,
                    search_maps: Iterable[str] = (), search_group: str = ""
                    ) -> place_pb2.QueryPlaceResponse:
        """Looks a frame up in a map; ``response.result`` is its ``LoopResult``.

        Without ``add_frame`` this is a relocalisation query that changes nothing; with it the
        frame runs the map's loop detector and is kept (with ``client_frame_id``), like one frame
        of :meth:`stream_frames`. ``result_options`` (a ``ResultOptions`` or a mapping of its
        fields: ``top_k`` up to 50, ``include_correspondences``, ``include_fundamental``,
        ``include_relative_pose``) asks for the top-k candidates (``result.candidates``) and, for
        a verified loop, its inlier correspondences, fundamental matrix and relative pose (the
        last needs the frame's intrinsics). The matched frame's client id is
        ``result.match_client_frame_id``.

        ``search_maps`` (names) and ``search_group`` (a group given at creation, ``settings``
        ``{"group": ...}``) are other maps the frame is also looked up in, each as a
        relocalisation query: the places recognised there are ``response.inter_map`` (each with
        its ``map`` and ``result``), best first, one at most per map. ``NotFound`` naming an
        unknown map or group (nothing is added then).
        """
        request = place_pb2.QueryPlaceRequest(
            map=map_name, frame=as_frame(image, client_frame_id=client_frame_id),
            add_frame=add_frame, options=_result_options(result_options),
            request_id=_request_id(request_id), search_maps=list(search_maps),
            search_group=search_group)
        return self._unary(self._places.QueryPlace, request, map_name)

    def relocalize(self, images: Iterable[Image], maps: Iterable[str] = (), group: str = "",
                   result_options: place_pb2.ResultOptions | Mapping | None = None,
                   max_results: int = 0) -> place_pb2.RelocalizeResponse:
        """Relocalisation (a kidnapped robot, the start of a session): looks 1 to 10 frames up.

        ``images`` (anything :meth:`query_place` takes, e.g. the last few frames of one camera)
        are looked up in ``maps`` (names) and every map of ``group``, with no temporal
        consistency to wait for and nothing added. ``response.places`` lists the places
        recognised, one at most per map, best first: a map that recognised more of the frames
        (``frames_recognised``) first; each names the frame it is for (``frame_index``,
        ``client_frame_id``) and carries that frame's ``result``. ``max_results`` keeps the best
        few (0: all). ``NotFound`` naming an unknown map or group; ``InvalidArgument`` without
        maps, with no frame or more than 10, or naming a bad frame (``frames[i]``).
        """
        maps = list(maps)
        request = place_pb2.RelocalizeRequest(
            frames=[as_frame(image) for image in images], maps=maps, group=group,
            options=_result_options(result_options), max_results=max_results)
        # a router sends it to the shard of the first map, or of the group ("group:NAME")
        routed_by = maps[0] if maps else (f"group:{group}" if group else None)
        return self._unary(self._places.Relocalize, request, routed_by)

    def remove_frame(self, map_name: str, frame_id: int | None = None,
                     client_frame_id: str | None = None, *, request_id: str | None = None
                     ) -> list[int]:
        """Removes frames from a map (keyframe culling) and returns their ids.

        Give exactly one of ``frame_id`` (the id the frame got) and ``client_frame_id`` (every
        frame added with it; ``InvalidArgument`` otherwise). A removed frame is never a candidate
        again. ``NotFound`` for an unknown map or when no frame matches.
        """
        if (frame_id is None) == (client_frame_id is None):
            raise InvalidArgument("remove_frame takes exactly one of frame_id and client_frame_id")
        request = place_pb2.RemoveFrameRequest(map=map_name, request_id=_request_id(request_id))
        if frame_id is not None:
            request.frame_id = frame_id
        else:
            request.client_frame_id = client_frame_id
        return list(self._unary(self._places.RemoveFrame, request, map_name).removed_frame_ids)

    def stream_frames(self, map_name: str, frames: Iterable[Image], create_if_missing: bool = True,
                      settings: place_pb2.MapSettings | Mapping | None = None,
                      query_only: bool = False,
                      result_options: place_pb2.ResultOptions | Mapping | None = None,
                      search_maps: Iterable[str] = (), search_group: str = ""
                      ) -> Stream[place_pb2.StreamFramesResponse]:
        """Streams frames into a map; returns the :class:`Stream` of their answers, in order.

        ``frames`` may be lazy (a generator reading a camera): each is sent when gRPC flow
        control lets it, and the server answers one frame before reading the next. Each answer
        has its ``sequence`` (index in ``frames``) and either ``result`` (a ``LoopResult``) or
        ``error`` (this frame failed, e.g. an undecodable image; the stream goes on).
        ``settings`` (as in :meth:`create_map`) apply when ``create_if_missing`` creates the map;
        ``query_only`` looks every frame up without adding it; ``result_options`` as in
        :meth:`query_place`, for every frame, and so are ``search_maps`` and ``search_group``
        (each answer's ``inter_map``; an unknown map or group ends the stream with ``NotFound``).
        """
        config = place_pb2.StreamConfig(map=map_name, create_if_missing=create_if_missing,
                                        settings=_map_settings(settings), query_only=query_only,
                                        options=_result_options(result_options),
                                        search_maps=list(search_maps), search_group=search_group)

        def requests():
            yield place_pb2.StreamFramesRequest(config=config)
            for image in frames:
                yield place_pb2.StreamFramesRequest(frame=as_frame(image))

        return self._stream(self._places.StreamFrames, requests(), map_name)

    # Object recognition.

    def recognize_objects(self, image: Image,
                          intrinsics: common_pb2.CameraIntrinsics | Sequence[float],
                          names: Iterable[str] = (), classes: Iterable[str] = (),
                          include_inliers: bool = False, include_covariance: bool = False,
                          explain: bool = False) -> object_pb2.RecognizeObjectsResponse:
        """Recognises the known objects in one image; ``response.objects`` is best first.

        ``intrinsics`` as in :func:`recog_client.make_intrinsics` (required: poses are solved with
        them; they replace those of a given Frame). ``names`` and ``classes`` restrict the answer
        to those objects (empty: every object). Finding nothing is an empty list, not an error.
        For a SLAM that inserts the objects as landmarks, ``include_inliers`` fills each object's
        ``inliers_2d3d`` and ``include_covariance`` its ``covariance`` (6x6 of the pose,
        row-major, rotation first). ``explain`` fills ``response.explanations``: for every object
        the filter lets through, where it dropped out (``ObjectOutcome``) and with what evidence.
        """
        frame = common_pb2.Frame()
        frame.CopyFrom(as_frame(image))
        frame.intrinsics.CopyFrom(make_intrinsics(intrinsics))
        request = object_pb2.RecognizeObjectsRequest(
            frame=frame, filter=object_pb2.ObjectFilter(names=names, classes=classes),
            detection_options=object_pb2.DetectionOptions(include_inliers=include_inliers,
                                                          include_covariance=include_covariance),
            explain=explain)
        return self._unary(self._objects.RecognizeObjects, request)

    def stream_objects(self, frames: Iterable[Image],
                       intrinsics: common_pb2.CameraIntrinsics | Sequence[float],
                       names: Iterable[str] = (), classes: Iterable[str] = (),
                       include_inliers: bool = False, include_covariance: bool = False,
                       tracking: bool = True
                       ) -> Stream[object_pb2.StreamRecognizeObjectsResponse]:
        """Streams frames of one camera (StreamRecognizeObjects); returns the :class:`Stream` of
        their answers, in order.

        Each answer has its ``sequence``, its ``objects`` (as in :meth:`recognize_objects`) or an
        ``error`` (this frame failed; the stream goes on). With ``tracking`` (the default) an
        object found once is followed into the next frames from its last pose, at frame rate;
        each object's ``tracked`` says whether it was tracked or recognised in that frame.
        ``tracking=False`` recognises every frame on its own.
        """
        config = object_pb2.RecognitionConfig(
            filter=object_pb2.ObjectFilter(names=names, classes=classes),
            detection_options=object_pb2.DetectionOptions(include_inliers=include_inliers,
                                                          include_covariance=include_covariance),
            disable_tracking=not tracking)
        camera = make_intrinsics(intrinsics)

        def requests():
            yield object_pb2.StreamRecognizeObjectsRequest(config=config)
            for image in frames:
                frame = common_pb2.Frame()
                frame.CopyFrom(as_frame(image))
                frame.intrinsics.CopyFrom(camera)
                yield object_pb2.StreamRecognizeObjectsRequest(frame=frame)

        return self._stream(self._objects.StreamRecognizeObjects, requests())

    # Object model repository.

    def upload_model(self, model: bytes | str | os.PathLike, name: str = "",
                     tags: Iterable[str] = (), *, request_id: str | None = None
                     ) -> repository_pb2.ModelInfo:
        """Uploads a ``.robj`` model file (bytes or path) as a new version; returns its info.

        ``name`` empty keeps the name inside the file. The file is sent in chunks after a header
        with its size and SHA-256, which the server checks before storing anything, under the
        transfer deadline. When the server holds the first bytes of this file from an upload that
        broke off (this client's or another's), only the rest is sent: call again after a broken
        upload to resume it.
        """
        data = read_bytes(model)
        sha256 = hashlib.sha256(data).hexdigest()
        held = self._unary(self._repository.GetUploadStatus,
                           repository_pb2.GetUploadStatusRequest(sha256=sha256,
                                                                 size_bytes=len(data)))
        header = repository_pb2.PutModelHeader(name=name, tags=tags, sha256=sha256,
                                               size_bytes=len(data), offset=held.received_bytes,
                                               request_id=_request_id(request_id))

        def requests():
            yield repository_pb2.PutModelRequest(header=header)
            for offset in range(header.offset, len(data), UPLOAD_CHUNK_BYTES):
                yield repository_pb2.PutModelRequest(
                    chunk=data[offset:offset + UPLOAD_CHUNK_BYTES])

        return self._unary(self._repository.PutModel, requests(),
                           deadline=self.transfer_deadline).model

    def download_model(self, name: str, version: int = 0) -> bytes:
        """Returns the file of a model version (0: the latest), under the transfer deadline.

        ``DataLoss`` when the bytes received differ in size or SHA-256 from the ``ModelInfo``
        the server sent first; ``NotFound`` for an unknown model or version.
        """
        request = repository_pb2.GetModelRequest(name=name, version=version)
        info = None
        chunks = []
        for response in self._stream(self._repository.GetModel, request,
                                     deadline=self.transfer_deadline):
            if response.WhichOneof("response") == "info":
                info = response.info
            else:
                chunks.append(response.chunk)
        data = b"".join(chunks)
        if info is None:
            raise DataLoss(f"the download of model {name!r} carried no ModelInfo")
        if len(data) != info.size_bytes or hashlib.sha256(data).hexdigest() != info.sha256:
            raise DataLoss(f"model {name!r} version {info.version}: the download does not match "
                           f"its size ({info.size_bytes}) and SHA-256 ({info.sha256})")
        return data

    def list_models(self, name_prefix: str = "", object_class: str = "", tag: str = "",
                    page_size: int = 0) -> Iterator[repository_pb2.ModelInfo]:
        """The latest version of every model passing the filters (empty: any), by name, read
        lazily a page at a time (``page_size`` 0: the server's, 100)."""
        request = repository_pb2.ListModelsRequest(name_prefix=name_prefix,
                                                   object_class=object_class, tag=tag,
                                                   page_size=page_size)
        return self._pages(self._repository.ListModels, request, "models")

    def delete_model(self, name: str, *, request_id: str | None = None) -> int:
        """Deletes every version of a model; returns how many there were. ``NotFound``."""
        request = repository_pb2.DeleteModelRequest(name=name, request_id=_request_id(request_id))
        return self._unary(self._repository.DeleteModel, request).versions_deleted

    def watch_models(self, prefix: str = "", include_existing: bool = False
                     ) -> Stream[repository_pb2.WatchModelsResponse]:
        """The endless :class:`Stream` of changes to the models whose name starts with ``prefix``.

        Every upload and deletion from now on, in order; with ``include_existing``, first every
        version already stored (``MODEL_CHANGE_PUT``), then one ``MODEL_CHANGE_SYNCED``, with no
        change missed or repeated in between. ``cancel()`` (from any thread) stops watching,
        after which the iteration raises ``Cancelled``. A watcher that falls too far behind is
        ended with ``ResourceExhausted`` and should watch anew with ``include_existing``.
        """
        request = repository_pb2.WatchModelsRequest(name_prefix=prefix,
                                                    include_existing=include_existing)
        return self._stream(self._repository.WatchModels, request)

    # Operation.

    def check_health(self, service: str = "") -> str:
        """The server's health (grpc.health.v1 Check; ``service`` "" = the whole server) as a
        name: ``"SERVING"`` once its store is open, ``"NOT_SERVING"`` while it opens or drains.
        One attempt (a probe: the retry policy does not cover Health); ``Unavailable`` when
        nothing answers."""
        response = self._unary(self._health.Check, health_pb2.HealthCheckRequest(service=service))
        return health_pb2.HealthCheckResponse.ServingStatus.Name(response.status)

    def verify_store(self, mib_per_second: int = 0) -> admin_pb2.VerifyResponse:
        """Has the server read every file of its store and check every checksum now
        (Admin.Verify, needs the write right) at ``mib_per_second`` (0: the server's
        ``store.verify_mb_per_s``); returns what it read. ``DataLoss`` when it found damage (the
        server log names the file, and ``check_health("recog.store")`` says NOT_SERVING). The
        transfer deadline applies."""
        return self._unary(self._admin.Verify,
                           admin_pb2.VerifyRequest(mib_per_second=mib_per_second),
                           deadline=self.transfer_deadline)

    def store_status(self) -> admin_pb2.StoreStatusResponse:
        """What the server's store went through (Admin.StoreStatus): ``recovery``, set when a
        point-in-time recovery at start-up lost something (per map the frames before and after
        and the ids missing, maps lost whole, blobs lost, where the damaged files are kept), and
        ``last_check``, the last check of the store's files (``error`` empty when it found no
        damage), set once one has run."""
        return self._unary(self._admin.StoreStatus, admin_pb2.StoreStatusRequest())

    def checkpoint(self, directory: str | os.PathLike,
                   progress: Callable[[int, int], None] | None = None
                   ) -> admin_pb2.CheckpointManifest:
        """Downloads an online checkpoint of the server's whole store (Admin.Checkpoint, needs
        the write right) into the new directory ``directory`` and returns its manifest.

        The files arrive in ``<directory>.part``, are checked against the manifest's sizes
        (``DataLoss`` otherwise), synced, and the folder is renamed into place, so ``directory``
        is a whole checkpoint or absent. ``AlreadyExists`` when it exists. ``progress(bytes,
        total)`` is called as bytes arrive. The transfer deadline applies; ``recog admin
        restore`` puts the files in place for a new server.
        """
        target = Path(directory)
        if target.exists():
            raise AlreadyExists(f"{target} exists")
        part = target.with_name(target.name + ".part")
        if part.exists():
            for stale in part.iterdir():
                stale.unlink()
        part.mkdir(parents=True, exist_ok=True)
        manifest = None
        files: list[admin_pb2.CheckpointFile] = []
        current = None  # (the file being written, its bytes still to come)
        received = 0
        try:
            for response in self._stream(self._admin.Checkpoint, admin_pb2.CheckpointRequest(),
                                         deadline=self.transfer_deadline):
                if response.WhichOneof("response") == "manifest":
                    manifest = response.manifest
                    files = list(manifest.files)
                    continue
                chunk = response.chunk
                while chunk:
                    current = current or _open_next_file(part, files)
                    if current is None:
                        raise DataLoss("the checkpoint sent more bytes than its manifest lists")
                    file, left = current
                    piece = chunk[:left]
                    file.write(piece)
                    received += len(piece)
                    chunk = chunk[len(piece):]
                    current = (file, left - len(piece))
                    if current[1] == 0:
                        _sync_and_close(file)
                        current = None
                if progress is not None and manifest is not None:
                    progress(received, manifest.total_bytes)
            current = current or _open_next_file(part, files)  # the empty files at the end
        finally:
            if current is not None:
                current[0].close()
        if manifest is None or current is not None:
            raise DataLoss(f"the checkpoint ended after {received} bytes, short of its manifest")
        part.rename(target)
        return manifest
