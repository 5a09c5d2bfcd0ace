"""Frames for recogd from what a Python program holds: image files, NumPy / OpenCV arrays, or
features extracted on the robot.

An image is one of
- ``bytes`` (a JPEG or PNG file's contents) or a path (``str``/``os.PathLike``) of such a file;
- a NumPy array of ``uint8`` as OpenCV returns it: ``(h, w)`` or ``(h, w, 1)`` grey, ``(h, w, 3)``
  BGR (OpenCV's channel order), sent as raw pixels (``RawImage``, no compression on either side);
- a ``common_pb2.Features`` (see :func:`make_features`): keypoints and descriptors from the robot;
- a ready ``common_pb2.Frame``.
A rig map (``MapSettings.rig``, cameras from :func:`rig_camera`) takes frames of
:func:`make_rig_frame`: one image per camera, each a view (:func:`rig_view` for a view with depth
or a right image).
NumPy is optional: arrays are recognised only when NumPy is loaded (an array cannot exist
otherwise). Bad input raises :class:`recog_client.errors.InvalidArgument` (a ``ValueError``);
a missing file ``OSError``.
"""

import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from ._proto.recognition.v1 import common_pb2, place_pb2
from .errors import InvalidArgument

Image = Any  # bytes | str | os.PathLike | numpy.ndarray | common_pb2.Features | common_pb2.Frame
Matrix3 = Any  # 3 rows of 3 values | numpy.ndarray (3, 3) or (9,) | 9 values, row-major

_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
# The fields a view of a rig frame may carry (the rest is the rig's or the rig frame's).
_VIEW_FIELDS = {"encoded_image", "raw_image", "features", "depth", "right", "camera_id"}


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


LENSES = {"radtan": common_pb2.LENS_MODEL_RADTAN,
          "equidistant": common_pb2.LENS_MODEL_EQUIDISTANT,
          "double_sphere": common_pb2.LENS_MODEL_DOUBLE_SPHERE}


def make_intrinsics(intrinsics: common_pb2.CameraIntrinsics | Sequence[float],
                    lens: str = "radtan") -> common_pb2.CameraIntrinsics:
    """Returns camera intrinsics as a message.

    ``intrinsics`` is a ``CameraIntrinsics`` (returned as it is) or the sequence
    ``(fx, fy, cx, cy, *distortion)`` in pixels; ``lens`` names the model of the distortion
    coefficients: ``"radtan"`` (OpenCV's order, 0, 4, 5, 8, 12 or 14 of them), ``"equidistant"``
    (the Kannala-Brandt fisheye of cv::fisheye: k1 k2 k3 k4) or ``"double_sphere"`` (xi, alpha).
    The server checks the count.
    """
    if isinstance(intrinsics, common_pb2.CameraIntrinsics):
        return intrinsics
    if lens not in LENSES:
        raise InvalidArgument(f"lens {lens!r} is not one of {', '.join(LENSES)}")
    values = [float(v) for v in intrinsics]
    if len(values) < 4:
        raise InvalidArgument("intrinsics are (fx, fy, cx, cy, *distortion)")
    fx, fy, cx, cy, *distortion = values
    return common_pb2.CameraIntrinsics(fx=fx, fy=fy, cx=cx, cy=cy, distortion=distortion,
                                       lens=LENSES[lens])


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
    if (depth is not None or right is not None) and intrinsics is None:
        raise InvalidArgument("depth and right images need the frame's intrinsics")
    frame = common_pb2.Frame(timestamp=timestamp, client_frame_id=client_frame_id,
                             camera_id=camera_id,  # timestamp=None leaves the field unset
                             exclude_frame_ids=list(exclude_frame_ids))
    _set_image(frame, image)
    if intrinsics is not None:
        frame.intrinsics.CopyFrom(make_intrinsics(intrinsics))
    _set_structure(frame, depth, depth_scale, right, baseline)
    return frame


def _set_structure(frame: common_pb2.Frame, depth, depth_scale: float, right,
                   baseline: float) -> None:
    """Puts the depth or the right image of :func:`make_frame` (either may be None) into
    ``frame``."""
    if depth is not None and right is not None:
        raise InvalidArgument("a frame carries depth or a right image, not both")
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


def rig_camera(name: str, size: tuple[int, int],
               intrinsics: common_pb2.CameraIntrinsics | Sequence[float],
               rotation: Matrix3 = _IDENTITY, translation: Sequence[float] = (0.0, 0.0, 0.0),
               distortion: Sequence[float] = ()) -> place_pb2.RigCameraSettings:
    """One camera of a rig map, for ``MapSettings(rig=[...])``.

    ``name`` is the camera's name (1..128 characters of [A-Za-z0-9._-], unique in the rig), which
    the views of :func:`make_rig_frame` are keyed by; ``size`` ``(width, height)`` of its images
    in pixels; ``intrinsics`` as in :func:`make_intrinsics`, or ``distortion`` its OpenCV
    coefficients (none, 4, 5 or 8) given apart. The camera's pose in the body frame,
    T_body<-camera (X_body = R X_camera + t), is ``rotation`` R (3x3: rows, a NumPy array, or 9
    values row-major) and ``translation`` t (3 values, metres). ``InvalidArgument`` for a wrong
    number of values or distortion given twice; the server checks that R is a rotation.
    """
    if len(size) != 2:
        raise InvalidArgument(f"rig camera {name!r}: size is (width, height) in pixels")
    translation = [float(v) for v in translation]
    if len(translation) != 3:
        raise InvalidArgument(f"rig camera {name!r}: a translation is 3 values (metres), not "
                              f"{len(translation)}")
    camera = place_pb2.RigCameraSettings(
        name=name, intrinsics=make_intrinsics(intrinsics), width=size[0], height=size[1],
        body_pose=common_pb2.Pose(rotation=_rotation_values(name, rotation),
                                  translation=translation))
    if distortion:
        if camera.intrinsics.distortion:
            raise InvalidArgument(f"rig camera {name!r}: distortion given twice (in intrinsics "
                                  "and apart)")
        camera.intrinsics.distortion.extend(float(v) for v in distortion)
    return camera


def _rotation_values(name: str, rotation: Matrix3) -> list[float]:
    """The 9 values, row-major, of the rotation of :func:`rig_camera` ``name``: 3 rows of 3, a
    (3, 3) or (9,) array, or 9 values."""
    array = _ndarray(rotation)
    rows = array.tolist() if array is not None else list(rotation)
    if all(isinstance(row, Iterable) for row in rows):
        rows = [list(row) for row in rows]
        values = [v for row in rows for v in row] if [len(r) for r in rows] == [3, 3, 3] else []
    else:
        values = rows
    if len(values) != 9:
        raise InvalidArgument(f"rig camera {name!r}: a rotation is 3x3 (3 rows of 3, or 9 values "
                              "row-major)")
    return [float(v) for v in values]


def rig_view(image: Image, depth=None, depth_scale: float = 1000.0, right=None,
             baseline: float = 0.0) -> common_pb2.Frame:
    """A view of a rig frame with its 3D structure, for metric loops: ``image`` (any form in the
    module comment but a Frame) with ``depth`` or ``right`` and ``baseline`` as in
    :func:`make_frame`. The camera's intrinsics (without distortion) come from the rig, so the
    view carries none. A view without depth or right image needs no call: give the image."""
    view = common_pb2.Frame()
    _set_image(view, image)
    _set_structure(view, depth, depth_scale, right, baseline)
    return view


def make_rig_frame(views: Mapping[str, Image], timestamp: float | None = None,
                   client_frame_id: str = "", exclude_frame_ids: Sequence[int] = ()
                   ) -> common_pb2.Frame:
    """A frame of a rig map: ``views`` maps every camera's name to its image, in any form of the
    module comment, or to a Frame holding only the view's content and its ``depth`` or
    ``right`` image (see :func:`rig_view`). The views are sent in the mapping's order, each
    naming its camera (``camera_id``); the camera's intrinsics, size and pose come from the rig.

    ``timestamp``, ``client_frame_id`` and ``exclude_frame_ids`` (rig frame ids) are the rig
    frame's, as in :func:`make_frame`. The server refuses a frame that misses a camera of the
    rig or names an unknown one, or an image of another size than its camera's.
    ``InvalidArgument`` here for no views, or a view Frame that carries more than its content,
    depth and right image (a timestamp, client_frame_id, intrinsics, exclude_frame_ids, views,
    or another camera's ``camera_id``).
    """
    if not views:
        raise InvalidArgument("a rig frame has one view per camera of the rig, not none")
    frame = common_pb2.Frame(timestamp=timestamp, client_frame_id=client_frame_id,
                             exclude_frame_ids=list(exclude_frame_ids))
    for camera, image in views.items():
        view = frame.views.add()
        if isinstance(image, common_pb2.Frame):
            extra = [field.name for field, _ in image.ListFields()
                     if field.name not in _VIEW_FIELDS]
            if extra:
                raise InvalidArgument(f"the view of camera {camera!r} carries {', '.join(extra)}: "
                                      "a view holds only its image and its depth or right image")
            if image.camera_id not in ("", camera):
                raise InvalidArgument(f"the view of camera {camera!r} names camera "
                                      f"{image.camera_id!r}")
            view.CopyFrom(image)
        else:
            _set_image(view, image)
        view.camera_id = camera
    return frame


def as_frame(image: Image, timestamp: float | None = None,
             client_frame_id: str = "") -> common_pb2.Frame:
    """Returns ``image`` if it is a Frame, otherwise :func:`make_frame` of it."""
    if isinstance(image, common_pb2.Frame):
        return image
    return make_frame(image, timestamp, client_frame_id=client_frame_id)
