"""Frames for recogd from what a Python program holds: image files, NumPy / OpenCV arrays, or
features extracted on the robot.

An image is one of
- ``bytes`` (a JPEG or PNG file's contents) or a path (``str``/``os.PathLike``) of such a file;
- a NumPy array of ``uint8`` as OpenCV returns it: ``(h, w)`` or ``(h, w, 1)`` grey, ``(h, w, 3)``
  BGR (OpenCV's channel order), sent as raw pixels (``RawImage``, no compression on either side);
- a ``common_pb2.Features`` (see :func:`make_features`): keypoints and descriptors from the robot;
- a ready ``common_pb2.Frame``.
NumPy is optional: arrays are recognised only when NumPy is loaded (an array cannot exist
otherwise). Bad input raises :class:`recog_client.errors.InvalidArgument` (a ``ValueError``);
a missing file ``OSError``.
"""

import os
import sys
from collections.abc import Iterable, Sequence
from typing import Any

from ._proto.recognition.v1 import common_pb2
from .errors import InvalidArgument

Image = Any  # bytes | str | os.PathLike | numpy.ndarray | common_pb2.Features | common_pb2.Frame


def read_bytes(source: bytes | str | os.PathLike) -> bytes:
    """Returns ``source`` if it is bytes, otherwise the contents of the file at that path."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source)
    with open(source, "rb") as file:
        return file.read()


def _ndarray(value: object):
    """``value`` if it is a NumPy array, else None (NumPy is not imported for this)."""
    numpy = sys.modules.get("numpy")
    return value if numpy is not None and isinstance(value, numpy.ndarray) else None


def raw_image(array) -> common_pb2.RawImage:
    """A ``RawImage`` of a ``uint8`` array: ``(h, w)``/``(h, w, 1)`` grey or ``(h, w, 3)`` BGR."""
    if str(array.dtype) != "uint8":
        raise InvalidArgument(f"an image array must be uint8, not {array.dtype}")
    channels = 1 if array.ndim == 2 else (array.shape[2] if array.ndim == 3 else 0)
    if channels not in (1, 3) or array.shape[0] == 0 or array.shape[1] == 0:
        raise InvalidArgument(f"an image array must be (h, w), (h, w, 1) or (h, w, 3), not "
                              f"{tuple(array.shape)}")
    pixel_format = common_pb2.PIXEL_FORMAT_GRAY8 if channels == 1 else common_pb2.PIXEL_FORMAT_BGR8
    numpy = sys.modules["numpy"]
    return common_pb2.RawImage(width=array.shape[1], height=array.shape[0], format=pixel_format,
                               pixels=numpy.ascontiguousarray(array).tobytes())


def raw_depth(array) -> common_pb2.RawDepth:
    """A ``RawDepth`` of an ``(h, w)`` array: ``uint16`` (units of 1/scale metres) or ``float32``
    (metres)."""
    formats = {"uint16": common_pb2.DEPTH_FORMAT_U16, "float32": common_pb2.DEPTH_FORMAT_F32}
    if str(array.dtype) not in formats or array.ndim != 2:
        raise InvalidArgument(f"a depth array must be (h, w) of uint16 or float32, not "
                              f"{tuple(array.shape)} of {array.dtype}")
    numpy = sys.modules["numpy"]
    data = numpy.ascontiguousarray(array, dtype=array.dtype.newbyteorder("<")).tobytes()
    return common_pb2.RawDepth(width=array.shape[1], height=array.shape[0],
                               format=formats[str(array.dtype)], data=data)


def make_intrinsics(intrinsics: common_pb2.CameraIntrinsics | Sequence[float]
                    ) -> common_pb2.CameraIntrinsics:
    """Returns camera intrinsics as a message.

    ``intrinsics`` is a ``CameraIntrinsics`` (returned as it is) or the sequence
    ``(fx, fy, cx, cy, *distortion)`` in pixels, with 0, 4, 5, 8, 12 or 14 OpenCV distortion
    coefficients.
    """
    if isinstance(intrinsics, common_pb2.CameraIntrinsics):
        return intrinsics
    values = [float(v) for v in intrinsics]
    if len(values) < 4:
        raise InvalidArgument("intrinsics are (fx, fy, cx, cy, *distortion)")
    fx, fy, cx, cy, *distortion = values
    return common_pb2.CameraIntrinsics(fx=fx, fy=fy, cx=cx, cy=cy, distortion=distortion)


def make_features(keypoints: Iterable, descriptors, image_size: tuple[int, int] | None = None
                  ) -> common_pb2.Features:
    """Features extracted on the robot, for frames that save the bandwidth of an image.

    ``keypoints`` are OpenCV ``cv2.KeyPoint`` objects (``pt``, ``size``, ``angle``, ``response``,
    ``octave``) or tuples ``(x, y[, size[, angle[, response[, octave]]]])`` (defaults: 31,
    ORB's patch; -1, no angle; 0; 0); ``descriptors`` a
    ``uint8`` array with one row per keypoint (ORB: 32 bytes) or their bytes, one after the other.
    ``image_size`` is ``(width, height)`` of the image they come from (optional).
    """
    points = common_pb2.Keypoints()
    count = 0
    for keypoint in keypoints:
        if hasattr(keypoint, "pt"):
            values = (*keypoint.pt, keypoint.size, keypoint.angle, keypoint.response,
                      keypoint.octave)
        else:
            values = tuple(keypoint) + (31.0, -1.0, 0.0, 0)[len(keypoint) - 2:]
        if len(values) != 6:
            raise InvalidArgument("a keypoint is (x, y[, size[, angle[, response[, octave]]]])")
        x, y, size, angle, response, octave = values
        points.x.append(x)
        points.y.append(y)
        points.size.append(size)
        points.angle.append(angle)
        points.response.append(response)
        points.octave.append(int(octave))
        count += 1
    array = _ndarray(descriptors)
    data = array.tobytes() if array is not None else bytes(descriptors)
    if count == 0 or len(data) % count != 0:
        raise InvalidArgument(f"{len(data)} descriptor bytes for {count} keypoints")
    features = common_pb2.Features(keypoints=points, descriptors=data,
                                   descriptor_bytes=len(data) // count)
    if image_size is not None:
        features.image_width, features.image_height = image_size
    return features


def _set_image(frame: common_pb2.Frame, image: Image) -> None:
    """Puts ``image`` (anything but a Frame) into ``frame``'s content."""
    if isinstance(image, common_pb2.Features):
        frame.features.CopyFrom(image)
    elif _ndarray(image) is not None:
        frame.raw_image.CopyFrom(raw_image(image))
    else:
        frame.encoded_image = read_bytes(image)


def make_frame(image: Image, timestamp: float | None = None,
               intrinsics: common_pb2.CameraIntrinsics | Sequence[float] | None = None,
               client_frame_id: str = "", depth=None, depth_scale: float = 1000.0,
               right=None, baseline: float = 0.0, camera_id: str = "",
               exclude_frame_ids: Sequence[int] = ()) -> common_pb2.Frame:
    """Builds a frame of ``image`` (any form in the module comment but a Frame).

    ``timestamp`` is in seconds in the client's clock (None = unknown; 0.0 is a time),
    ``intrinsics`` as in
    :func:`make_intrinsics`, ``client_frame_id`` free text (at most 128 bytes) that the server
    echoes and returns with every match, ``camera_id`` free text for the server's logs.

    Metric loops (place maps) need the frame's 3D structure and its ``intrinsics`` (without
    distortion): either ``depth``, an aligned depth image (a 16-bit PNG as bytes or path in units
    of 1/``depth_scale`` metres, 1000 = millimetres; a ``uint16`` or ``float32`` (metres) array;
    or a ready ``DepthImage``), or ``right``, the right image of a rectified stereo pair (file,
    bytes or array) with ``baseline`` in metres. ``InvalidArgument`` for both at once,
    intrinsics missing, or a right image without a positive baseline.

    ``exclude_frame_ids`` (place maps): frame ids, as the server returned them, that are never
    candidates for this frame — a SLAM's keyframes covisible with it (at most 1000).
    """
    frame = common_pb2.Frame(timestamp=timestamp, client_frame_id=client_frame_id,
                             camera_id=camera_id,  # timestamp=None leaves the field unset
                             exclude_frame_ids=list(exclude_frame_ids))
    _set_image(frame, image)
    if intrinsics is not None:
        frame.intrinsics.CopyFrom(make_intrinsics(intrinsics))
    if depth is not None and right is not None:
        raise InvalidArgument("a frame carries depth or a right image, not both")
    if (depth is not None or right is not None) and intrinsics is None:
        raise InvalidArgument("depth and right images need the frame's intrinsics")
    if isinstance(depth, common_pb2.DepthImage):
        frame.depth.CopyFrom(depth)
    elif _ndarray(depth) is not None:
        frame.depth.raw.CopyFrom(raw_depth(depth))
        frame.depth.scale = depth_scale
    elif depth is not None:
        frame.depth.encoded = read_bytes(depth)
        frame.depth.scale = depth_scale
    if right is not None:
        if not baseline > 0:
            raise InvalidArgument("a right image needs the stereo baseline in metres (> 0)")
        if _ndarray(right) is not None:
            frame.right.raw_image.CopyFrom(raw_image(right))
        else:
            frame.right.encoded_image = read_bytes(right)
        frame.right.baseline_m = baseline
    return frame


def as_frame(image: Image, timestamp: float | None = None,
             client_frame_id: str = "") -> common_pb2.Frame:
    """Returns ``image`` if it is a Frame, otherwise :func:`make_frame` of it."""
    if isinstance(image, common_pb2.Frame):
        return image
    return make_frame(image, timestamp, client_frame_id=client_frame_id)
