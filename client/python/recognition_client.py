"""A thin Python client of the recognition server (recogd), API ``recognition.v1``.

The generated stubs must be importable: put the directory CMake writes them to
(``<build>/python``, target ``recog_python_stubs``) on ``sys.path`` or ``PYTHONPATH``.

Images are given as the bytes of a JPEG or PNG file, as the path of such a file, or as a ready
``common_pb2.Frame`` (for raw pixels, client-side features, intrinsics or a ``client_frame_id``;
see :func:`make_frame`). Results are the generated protobuf messages, documented in
``proto/recognition/v1/*.proto``.

Errors: every method raises ``grpc.RpcError`` when the server refuses a call or cannot be
reached; ``error.code()`` is the canonical ``grpc.StatusCode`` (``NOT_FOUND``,
``ALREADY_EXISTS``, ``INVALID_ARGUMENT``, ``UNAVAILABLE``, ...) and ``error.details()`` the
server's message. Streams of frames report a single frame's failure inside that frame's
response (``response.error``) and go on. :meth:`RecognitionClient.download_model` raises
``ValueError`` when the downloaded bytes do not match the size and SHA-256 the server announced.

Example::

    with RecognitionClient("127.0.0.1:50051") as client:
        client.create_map("lab", {"temporal_matches": 3})
        for response in client.stream_frames("lab", ["1.jpg", "2.jpg"]):
            print(response.sequence, response.result.status)
"""

import hashlib
import os
from collections.abc import Iterable, Iterator, Mapping, Sequence

import grpc

from recognition.v1 import (common_pb2, object_pb2, object_pb2_grpc, place_pb2, place_pb2_grpc,
                            repository_pb2, repository_pb2_grpc)

#: Size of the chunks :meth:`RecognitionClient.upload_model` sends.
UPLOAD_CHUNK_BYTES = 1 << 20
#: The metadata header that names a call's place map for a router of shards (proto/routing.h).
MAP_HEADER = "x-recog-map"

Image = bytes | str | os.PathLike | common_pb2.Frame


def read_bytes(source: bytes | str | os.PathLike) -> bytes:
    """Returns ``source`` if it is bytes, otherwise the contents of the file at that path."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source)
    with open(source, "rb") as file:
        return file.read()


def make_intrinsics(intrinsics: common_pb2.CameraIntrinsics | Sequence[float]
                    ) -> common_pb2.CameraIntrinsics:
    """Returns camera intrinsics as a message.

    ``intrinsics`` is a ``CameraIntrinsics`` (returned as it is) or the sequence
    ``(fx, fy, cx, cy, *distortion)`` in pixels, with 0, 4, 5, 8, 12 or 14 OpenCV distortion
    coefficients.
    """
    if isinstance(intrinsics, common_pb2.CameraIntrinsics):
        return intrinsics
    fx, fy, cx, cy, *distortion = intrinsics
    return common_pb2.CameraIntrinsics(fx=fx, fy=fy, cx=cx, cy=cy, distortion=distortion)


def make_frame(image: bytes | str | os.PathLike, timestamp: float = 0.0,
               intrinsics: common_pb2.CameraIntrinsics | Sequence[float] | None = None,
               client_frame_id: str = "",
               depth: bytes | str | os.PathLike | common_pb2.DepthImage | None = None,
               depth_scale: float = 1000.0,
               right: bytes | str | os.PathLike | None = None,
               baseline: float = 0.0) -> common_pb2.Frame:
    """Builds a frame from a JPEG or PNG image (bytes or path).

    ``timestamp`` is in seconds in the client's clock (0 = unknown), ``intrinsics`` as in
    :func:`make_intrinsics`, ``client_frame_id`` free text (at most 128 bytes) that the server
    echoes in its answer.

    Metric loops (place maps) need the frame's 3D structure and its ``intrinsics`` (without
    distortion): either ``depth``, an aligned depth image (the bytes or path of a 16-bit PNG in
    units of 1/``depth_scale`` metres, 1000 = millimetres; or a ready ``DepthImage``, e.g. raw
    float metres), or ``right``, the right image of a rectified stereo pair (JPEG or PNG) with
    ``baseline`` in metres. ``ValueError`` for both at once, intrinsics missing, or a right image
    without a positive baseline.
    """
    frame = common_pb2.Frame(encoded_image=read_bytes(image), timestamp=timestamp,
                             client_frame_id=client_frame_id)
    if intrinsics is not None:
        frame.intrinsics.CopyFrom(make_intrinsics(intrinsics))
    if depth is not None and right is not None:
        raise ValueError("a frame carries depth or a right image, not both")
    if (depth is not None or right is not None) and intrinsics is None:
        raise ValueError("depth and right images need the frame's intrinsics")
    if isinstance(depth, common_pb2.DepthImage):
        frame.depth.CopyFrom(depth)
    elif depth is not None:
        frame.depth.encoded = read_bytes(depth)
        frame.depth.scale = depth_scale
    if right is not None:
        if not baseline > 0:
            raise ValueError("a right image needs the stereo baseline in metres (> 0)")
        frame.right.encoded_image = read_bytes(right)
        frame.right.baseline_m = baseline
    return frame


def _as_frame(image: Image, timestamp: float = 0.0, client_frame_id: str = "") -> common_pb2.Frame:
    """Returns ``image`` if it is a Frame, otherwise a frame of it with ``timestamp`` and
    ``client_frame_id``."""
    if isinstance(image, common_pb2.Frame):
        return image
    return make_frame(image, timestamp, client_frame_id=client_frame_id)


def _result_options(options: place_pb2.ResultOptions | Mapping | None) -> place_pb2.ResultOptions:
    """Returns result options given as a message, a mapping of its fields (``top_k``,
    ``include_correspondences``, ``include_fundamental``, ``include_relative_pose``), or None."""
    if isinstance(options, place_pb2.ResultOptions):
        return options
    return place_pb2.ResultOptions(**(options or {}))


def _map_settings(settings: place_pb2.MapSettings | Mapping | None) -> place_pb2.MapSettings:
    """Returns map settings given as a message, a mapping of its fields, or None (defaults)."""
    if isinstance(settings, place_pb2.MapSettings):
        return settings
    return place_pb2.MapSettings(**(settings or {}))


class RecognitionClient:
    """A connection to recogd and one method per RPC of its three services.

    Arguments:
        target: the server's ``host:port``.
        token: bearer token sent with every call (``authorization: Bearer <token>``), or None
            when the server runs without a token file.
        root_certificates: PEM bytes of the certificate authority of the server's TLS
            certificate; None connects without TLS.
        timeout: deadline in seconds of every call except :meth:`stream_frames` and
            :meth:`watch_models`, which last until their caller stops them.

    The client is a context manager; :meth:`close` releases the channel.
    """

    def __init__(self, target: str = "127.0.0.1:50051", token: str | None = None,
                 root_certificates: bytes | None = None, timeout: float = 10.0):
        """Opens the channel (lazily: the first call connects)."""
        if root_certificates is None:
            self._channel = grpc.insecure_channel(target)
        else:
            credentials = grpc.ssl_channel_credentials(root_certificates=root_certificates)
            self._channel = grpc.secure_channel(target, credentials)
        self._metadata = (("authorization", f"Bearer {token}"),) if token else ()
        self._timeout = timeout
        self._places = place_pb2_grpc.PlaceRecognitionStub(self._channel)
        self._objects = object_pb2_grpc.ObjectRecognitionStub(self._channel)
        self._repository = repository_pb2_grpc.ObjectRepositoryStub(self._channel)

    def close(self) -> None:
        """Closes the channel; calls in progress are cancelled."""
        self._channel.close()

    def __enter__(self) -> "RecognitionClient":
        """Returns the client itself."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Closes the client."""
        self.close()

    def _call(self, method, request, map_name: str | None = None):
        """Runs a unary call with the client's deadline and credentials; a call about a place map
        also carries the map in ``x-recog-map``, by which a router of shards places it."""
        return method(request, timeout=self._timeout, metadata=self._with_map(map_name))

    def _with_map(self, map_name: str | None) -> tuple:
        """The call metadata: credentials, and the routing header of a call about a map."""
        return self._metadata + ((MAP_HEADER, map_name),) if map_name else self._metadata

    def _all_pages(self, method, request, field: str) -> list:
        """Runs a paged listing call until its last page; returns the items of ``field``."""
        items = []
        while True:
            response = self._call(method, request)
            items.extend(getattr(response, field))
            if not response.next_page_token:
                return items
            request.page_token = response.next_page_token

    # Place recognition.

    def create_map(self, name: str, settings: place_pb2.MapSettings | Mapping | None = None
                   ) -> place_pb2.MapInfo:
        """Creates an empty map and returns its description.

        ``settings`` is a ``MapSettings``, a mapping of its fields (e.g.
        ``{"temporal_matches": 0, "recent_frames": 1}``) or None; unset fields take the server's
        defaults. ``ALREADY_EXISTS`` when the name is taken.
        """
        request = place_pb2.CreateMapRequest(name=name, settings=_map_settings(settings))
        return self._call(self._places.CreateMap, request, name).map

    def get_map(self, name: str) -> place_pb2.MapInfo:
        """Returns the description of a map (``NOT_FOUND`` when there is none)."""
        return self._call(self._places.GetMap, place_pb2.GetMapRequest(name=name), name).map

    def list_maps(self, page_size: int = 0) -> list[place_pb2.MapInfo]:
        """Returns every map, by name, reading all pages (``page_size`` 0: the server's)."""
        request = place_pb2.ListMapsRequest(page_size=page_size)
        return self._all_pages(self._places.ListMaps, request, "maps")

    def delete_map(self, name: str) -> int:
        """Deletes a map and its frames; returns how many frames it had."""
        response = self._call(self._places.DeleteMap, place_pb2.DeleteMapRequest(name=name),
                              name)
        return response.frames_deleted

    def add_frame(self, map_name: str, image: Image, timestamp: float = 0.0,
                  client_frame_id: str = "") -> place_pb2.AddFrameResponse:
        """Adds a frame to a map without querying it; the response carries its ``frame_id``.

        ``timestamp`` (seconds, 0 = unknown) and ``client_frame_id`` (the client's own id of the
        frame, e.g. a SLAM keyframe id: the map keeps it and returns it whenever the frame is a
        match) are used when ``image`` is not already a Frame.
        """
        request = place_pb2.AddFrameRequest(
            map=map_name, frame=_as_frame(image, timestamp, client_frame_id))
        return self._call(self._places.AddFrame, request, map_name)

    def query_place(self, map_name: str, image: Image, add_frame: bool = False,
                    result_options: place_pb2.ResultOptions | Mapping | None = None,
                    client_frame_id: str = "") -> place_pb2.QueryPlaceResponse:
        """Looks a frame up in a map; ``response.result`` is its ``LoopResult``.

        Without ``add_frame`` this is a relocalisation query that changes nothing; with it the
        frame runs the map's loop detector and is kept (with ``client_frame_id``), like one frame
        of :meth:`stream_frames`. ``result_options`` (a ``ResultOptions`` or a mapping of its
        fields, e.g. ``{"top_k": 5, "include_correspondences": True}``) asks for the top-k
        candidates (``result.candidates``, at most 50) and the inlier correspondences of a verified
        loop (``result.inlier_correspondences``). The matched frame's client id is
        ``result.match_client_frame_id``.
        """
        request = place_pb2.QueryPlaceRequest(
            map=map_name, frame=_as_frame(image, client_frame_id=client_frame_id),
            add_frame=add_frame, options=_result_options(result_options))
        return self._call(self._places.QueryPlace, request, map_name)

    def remove_frame(self, map_name: str, frame_id: int | None = None,
                     client_frame_id: str | None = None) -> list[int]:
        """Removes frames from a map (keyframe culling) and returns their ids.

        Give exactly one of ``frame_id`` (the id the frame got) and ``client_frame_id`` (every
        frame added with it). A removed frame is never a candidate again. ``NOT_FOUND`` for an
        unknown map or when no frame matches.
        """
        if (frame_id is None) == (client_frame_id is None):
            raise ValueError("remove_frame takes exactly one of frame_id and client_frame_id")
        request = place_pb2.RemoveFrameRequest(map=map_name)
        if frame_id is not None:
            request.frame_id = frame_id
        else:
            request.client_frame_id = client_frame_id
        response = self._call(self._places.RemoveFrame, request, map_name)
        return list(response.removed_frame_ids)

    def stream_frames(self, map_name: str, frames: Iterable[Image], create_if_missing: bool = True,
                      settings: place_pb2.MapSettings | Mapping | None = None,
                      query_only: bool = False,
                      result_options: place_pb2.ResultOptions | Mapping | None = None
                      ) -> Iterator[place_pb2.StreamFramesResponse]:
        """Streams frames into a map; returns the iterator of their answers, in frame order.

        ``frames`` may be lazy (a generator reading a camera): each is sent when gRPC flow
        control lets it, and the server answers one frame before reading the next. Each answer
        has its ``sequence`` (index in ``frames``) and either ``result`` (a ``LoopResult``) or
        ``error`` (this frame failed, e.g. an undecodable image; the stream goes on).
        ``settings`` (as in :meth:`create_map`) apply when ``create_if_missing`` creates the map;
        ``query_only`` looks every frame up without adding it; ``result_options`` as in
        :meth:`query_place`, for every frame.

        The returned object is also the ``grpc.Call``: ``cancel()`` ends the stream from any
        thread. An error of the whole stream raises ``grpc.RpcError`` during the iteration; so
        does an exception raised while reading ``frames`` (a missing file, say), which aborts the
        stream with ``UNKNOWN`` ("Exception iterating requests!").
        """
        config = place_pb2.StreamConfig(map=map_name, create_if_missing=create_if_missing,
                                        settings=_map_settings(settings), query_only=query_only,
                                        options=_result_options(result_options))

        def requests():
            yield place_pb2.StreamFramesRequest(config=config)
            for image in frames:
                yield place_pb2.StreamFramesRequest(frame=_as_frame(image))

        return self._places.StreamFrames(requests(), metadata=self._with_map(map_name))

    # Object recognition.

    def recognize_objects(self, image: Image,
                          intrinsics: common_pb2.CameraIntrinsics | Sequence[float],
                          names: Iterable[str] = (), classes: Iterable[str] = (),
                          include_inliers: bool = False, include_covariance: bool = False
                          ) -> object_pb2.RecognizeObjectsResponse:
        """Recognises the known objects in one image; ``response.objects`` is best first.

        ``intrinsics`` as in :func:`make_intrinsics` (required: poses are solved with them; they
        replace those of a given Frame). ``names`` and ``classes`` restrict the answer to those
        objects (empty: every object). Finding nothing is an empty list, not an error.
        For a SLAM that inserts the objects as landmarks, ``include_inliers`` fills each object's
        ``inliers_2d3d`` (pixel, model point, point id of every RANSAC inlier) and
        ``include_covariance`` its ``covariance`` (6x6 of the pose, row-major, rotation first).
        """
        frame = common_pb2.Frame()
        frame.CopyFrom(_as_frame(image))
        frame.intrinsics.CopyFrom(make_intrinsics(intrinsics))
        request = object_pb2.RecognizeObjectsRequest(
            frame=frame, filter=object_pb2.ObjectFilter(names=names, classes=classes),
            detection_options=object_pb2.DetectionOptions(include_inliers=include_inliers,
                                                          include_covariance=include_covariance))
        return self._call(self._objects.RecognizeObjects, request)

    def stream_objects(self, frames: Iterable[Image],
                       intrinsics: common_pb2.CameraIntrinsics | Sequence[float],
                       names: Iterable[str] = (), classes: Iterable[str] = (),
                       include_inliers: bool = False, include_covariance: bool = False,
                       tracking: bool = True
                       ) -> Iterator[object_pb2.StreamRecognizeObjectsResponse]:
        """Streams frames of one camera; returns the iterator of their answers, in frame order.

        Each answer has its ``sequence``, its ``objects`` (as in :meth:`recognize_objects`) or an
        ``error`` (this frame failed; the stream goes on). With ``tracking`` (the default) an
        object found once is followed into the next frames from its last pose, at frame rate;
        each object's ``tracked`` says whether it was tracked or recognised in that frame.
        ``tracking=False`` recognises every frame on its own. Flow control and cancelling as in
        :meth:`stream_frames`.
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
                frame.CopyFrom(_as_frame(image))
                frame.intrinsics.CopyFrom(camera)
                yield object_pb2.StreamRecognizeObjectsRequest(frame=frame)

        return self._objects.StreamRecognizeObjects(requests(), metadata=self._metadata)

    # Object model repository.

    def upload_model(self, model: bytes | str | os.PathLike, name: str = "",
                     tags: Iterable[str] = ()) -> repository_pb2.ModelInfo:
        """Uploads a ``.robj`` model file (bytes or path) as a new version; returns its info.

        ``name`` empty keeps the name inside the file. The file is sent in chunks after a header
        with its size and SHA-256, which the server checks before storing anything. When the
        server holds the first bytes of this file from an upload that broke off (this client's
        or another's), only the rest is sent; call again after a broken upload to resume it.
        """
        data = read_bytes(model)
        sha256 = hashlib.sha256(data).hexdigest()
        held = self._call(self._repository.GetUploadStatus,
                          repository_pb2.GetUploadStatusRequest(sha256=sha256,
                                                                size_bytes=len(data)))
        header = repository_pb2.PutModelHeader(name=name, tags=tags, sha256=sha256,
                                               size_bytes=len(data), offset=held.received_bytes)

        def requests():
            yield repository_pb2.PutModelRequest(header=header)
            for offset in range(header.offset, len(data), UPLOAD_CHUNK_BYTES):
                yield repository_pb2.PutModelRequest(
                    chunk=data[offset:offset + UPLOAD_CHUNK_BYTES])

        return self._call(self._repository.PutModel, requests()).model

    def download_model(self, name: str, version: int = 0) -> bytes:
        """Returns the file of a model version (0: the latest).

        Raises ``ValueError`` when the bytes received differ in size or SHA-256 from the
        ``ModelInfo`` the server sent first.
        """
        request = repository_pb2.GetModelRequest(name=name, version=version)
        info = None
        chunks = []
        for response in self._call(self._repository.GetModel, request):
            if response.WhichOneof("response") == "info":
                info = response.info
            else:
                chunks.append(response.chunk)
        data = b"".join(chunks)
        if info is None:
            raise ValueError(f"the download of model {name!r} carried no ModelInfo")
        if len(data) != info.size_bytes or hashlib.sha256(data).hexdigest() != info.sha256:
            raise ValueError(f"model {name!r} version {info.version}: the download does not "
                             f"match its size ({info.size_bytes}) and SHA-256 ({info.sha256})")
        return data

    def list_models(self, name_prefix: str = "", object_class: str = "", tag: str = ""
                    ) -> list[repository_pb2.ModelInfo]:
        """Returns the latest version of every model passing the filters (empty: any), by name."""
        request = repository_pb2.ListModelsRequest(name_prefix=name_prefix,
                                                   object_class=object_class, tag=tag)
        return self._all_pages(self._repository.ListModels, request, "models")

    def delete_model(self, name: str) -> int:
        """Deletes every version of a model; returns how many there were."""
        response = self._call(self._repository.DeleteModel,
                              repository_pb2.DeleteModelRequest(name=name))
        return response.versions_deleted

    def watch_models(
        self, prefix: str = "", include_existing: bool = False
    ) -> Iterator[repository_pb2.WatchModelsResponse]:
        """Returns the endless iterator of changes to the models whose name starts with ``prefix``.

        Every upload and deletion from now on, in order; with ``include_existing``, first every
        version already stored (``MODEL_CHANGE_PUT``), then one ``MODEL_CHANGE_SYNCED``, with no
        change missed or repeated in between. The returned object is also the ``grpc.Call``:
        ``cancel()`` (from any thread) stops watching, after which the iteration raises
        ``grpc.RpcError`` with ``CANCELLED``. A watcher that falls too far behind is ended with
        ``RESOURCE_EXHAUSTED`` and should watch anew with ``include_existing``.
        """
        request = repository_pb2.WatchModelsRequest(
            name_prefix=prefix, include_existing=include_existing
        )
        return self._repository.WatchModels(request, metadata=self._metadata)
