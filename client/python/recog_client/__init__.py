"""recog_client: the Python client of recogd, the place and object recognition server.

:class:`RecognitionClient` has a method per call of the API (``recognition.v1``); frames come from
image files, NumPy / OpenCV arrays or client-side features, one per camera for a rig map
(:mod:`recog_client.frames`); failures are :class:`RecogError` subclasses
(:mod:`recog_client.errors`). The generated protobuf modules are re-exported here
(``recog_client.place_pb2``, ...), as are the option messages ``ResultOptions`` and
``MapSettings``. See client/python/README.md.
"""

from ._proto.recognition.v1 import (admin_pb2, common_pb2, object_pb2, place_pb2,
                                    repository_pb2)
from ._version import __version__
from .client import (DEFAULT_TARGET, MAP_HEADER, SHARD_HEADER, RecognitionClient, Stream,
                     service_config)
from .errors import (Aborted, AlreadyExists, Cancelled, DataLoss, DeadlineExceeded,
                     FailedPrecondition, Internal, InvalidArgument, NotFound, OutOfRange,
                     PermissionDenied, RecogError, ResourceExhausted, Unauthenticated,
                     Unavailable, Unimplemented, Unknown)
from .frames import (make_features, make_frame, make_intrinsics, make_rig_frame, read_bytes,
                     rig_camera, rig_view)

ResultOptions = place_pb2.ResultOptions
MapSettings = place_pb2.MapSettings

__all__ = [
    "__version__", "RecognitionClient", "Stream", "service_config", "DEFAULT_TARGET",
    "MAP_HEADER", "SHARD_HEADER", "ResultOptions", "MapSettings", "make_frame", "make_features",
    "make_intrinsics", "make_rig_frame", "rig_camera", "rig_view", "read_bytes", "admin_pb2",
    "common_pb2", "object_pb2", "place_pb2",
    "repository_pb2", "RecogError", "Aborted", "AlreadyExists", "Cancelled", "DataLoss",
    "DeadlineExceeded", "FailedPrecondition", "Internal", "InvalidArgument", "NotFound",
    "OutOfRange", "PermissionDenied", "ResourceExhausted", "Unauthenticated", "Unavailable",
    "Unimplemented", "Unknown",
]
