"""Streams a folder of images into a place map and prints each loop closure as it happens.

The images (.jpg, .jpeg, .png) are sent in natural order of their names (2.jpg before 10.jpg);
the map is created with the server's default settings when it does not exist, and a map that
exists gets the frames after its own. The last line sums up, e.g.
`4 frames streamed into map 'lab', 0 loops`. Example::

    .venv/bin/python client/python/examples/stream_folder.py --map corridor tests/data/corridor

(with the package installed, see client/python/README.md; or PYTHONPATH=build/python). Exit
status: 0 when the folder was streamed, 1 on an error (one line on stderr), 2 on a bad command
line.

Or a ROS 1 bag's image topic instead of the folder (``--bag FILE --topic T``, read with Debian's
python3-rosbag): sensor_msgs/Image in mono8, rgb8 or bgr8 (sent as raw pixels) or
sensor_msgs/CompressedImage (its JPEG or PNG bytes), in the order of their header stamps, each
stamp the frame's timestamp (the map's tau_c then counts seconds: recent_seconds).
"""

import argparse
import re
import sys
from pathlib import Path

try:
    from recog_client import RecogError, RecognitionClient, Unavailable, make_frame, place_pb2
except ModuleNotFoundError as missing:  # not the interpreter of the client's environment
    sys.exit(f"stream_folder: {sys.executable} has no module {missing.name}: run this with "
             ".venv/bin/python (client/python/README.md, Installing) or, without installing, "
             "PYTHONPATH=build/python /usr/bin/python3")

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png"}
#: sensor_msgs/Image encodings --bag takes: channels of a pixel.
BAG_ENCODINGS = {"mono8": 1, "rgb8": 3, "bgr8": 3}
BAG_IMAGE_TYPES = ("sensor_msgs/Image", "sensor_msgs/CompressedImage")


class BagError(Exception):
    """A bag that cannot be streamed (its message is the example's one line)."""


def natural_key(name: str) -> list:
    """Sort key comparing the digit runs of a name as numbers: "2.jpg" < "10.jpg"."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def list_images(folder: Path) -> list[Path]:
    """Returns the images directly in ``folder``, in natural order of their names."""
    images = [path for path in folder.iterdir()
              if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(images, key=lambda path: natural_key(path.name))


def bag_image(message):
    """The image of a bag's message as the client takes it: the bytes of a CompressedImage, a
    (h, w) grey or (h, w, 3) BGR array of a raw Image."""
    if message._type == "sensor_msgs/CompressedImage":
        return bytes(message.data)
    channels = BAG_ENCODINGS.get(message.encoding)
    if channels is None:
        raise BagError(f"encoding {message.encoding!r} of the image at stamp "
                       f"{message.header.stamp.to_sec():.3f} is not mono8, rgb8 or bgr8")
    import numpy  # pylint: disable=import-outside-toplevel
    rows = numpy.frombuffer(message.data, numpy.uint8).reshape(message.height, message.step)
    pixels = rows[:, :message.width * channels].reshape(message.height, message.width, channels)
    if message.encoding == "rgb8":
        pixels = pixels[:, :, ::-1]  # the client's arrays are OpenCV's BGR
    return pixels[:, :, 0] if channels == 1 else pixels


def read_bag(path: Path, topic: str | None) -> list:
    """The frames of ``topic`` in the bag at ``path``, in header-stamp order, as frames with their
    stamps as timestamps; BagError for anything that keeps them from being streamed."""
    try:
        import rosbag  # pylint: disable=import-outside-toplevel
    except ImportError as error:
        raise BagError(f"--bag needs Python's rosbag module ({error}): install Debian's "
                       "python3-rosbag and run this with /usr/bin/python3 (or a .venv made "
                       "with --system-site-packages)") from None
    try:
        with rosbag.Bag(str(path)) as bag:
            topics = bag.get_type_and_topic_info().topics
            if topic not in topics or topics[topic].msg_type not in BAG_IMAGE_TYPES:
                listed = ", ".join(f"{name} ({info.msg_type}, {info.message_count} messages)"
                                   for name, info in sorted(topics.items()))
                wanted = f"no image topic {topic}" if topic else "give --topic"
                raise BagError(f"{path}: {wanted}; its topics: {listed or 'none'}")
            messages = [message for _, message, _ in bag.read_messages(topics=[topic])]
    except (rosbag.ROSBagException, OSError) as error:
        raise BagError(f"{path}: {error}") from None
    messages.sort(key=lambda message: message.header.stamp)
    try:
        return [make_frame(bag_image(message), timestamp=message.header.stamp.to_sec())
                for message in messages]
    except BagError as error:
        raise BagError(f"{path}: {error}") from None


def parse_arguments() -> argparse.Namespace:
    """Reads the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--server", help="recogd's host:port (default: RECOG_SERVER, else "
                        "127.0.0.1:50051)")
    parser.add_argument("--map", required=True, help="name of the map to stream into")
    parser.add_argument("--token-file", help="file of the bearer token, when the server has "
                        "tokens (default: RECOG_TOKEN_FILE)")
    parser.add_argument("images", type=Path, nargs="?", help="folder of the images")
    parser.add_argument("--bag", type=Path, help="a ROS 1 bag instead of the folder (Debian's "
                        "python3-rosbag reads it)")
    parser.add_argument("--topic", help="with --bag: its image topic")
    arguments = parser.parse_args()
    if (arguments.images is None) == (arguments.bag is None):
        parser.error("give either a folder of images or --bag FILE --topic TOPIC")
    if arguments.topic and not arguments.bag:
        parser.error("--topic goes with --bag")
    return arguments


def fail(message: str) -> int:
    """Prints ``message`` as the program's one line on stderr; the exit status 1."""
    print(f"stream_folder: {message}", file=sys.stderr)
    return 1


def plural(count: int, noun: str) -> str:
    """``count`` and ``noun``, with an s unless it is one."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def main() -> int:
    """Streams the folder; returns the exit status (1 when the stream failed)."""
    arguments = parse_arguments()
    if arguments.bag:
        try:
            images = read_bag(arguments.bag, arguments.topic)
        except BagError as error:
            return fail(str(error))
        labels = [f"stamp {frame.timestamp:.3f}" for frame in images]
    else:
        if not arguments.images.is_dir():
            return fail(f"{arguments.images}: no such folder")
        images = list_images(arguments.images)
        labels = [path.name for path in images]
    if not images:
        return fail(f"{arguments.bag}: no message on {arguments.topic}" if arguments.bag
                    else f"{arguments.images}: no .jpg, .jpeg or .png image in it")
    names = {}  # frame id in the map -> "id (file name)", for this run's frames
    loops = candidates = failed = 0
    client = None
    try:
        client = RecognitionClient(arguments.server, token_file=arguments.token_file)
        for response in client.stream_frames(arguments.map, images):
            if response.HasField("error"):  # this frame only; the stream goes on
                failed += 1
                print(f"{labels[response.sequence]}: error {response.error.code}: "
                      f"{response.error.message}", file=sys.stderr)
                continue
            result, name = response.result, labels[response.sequence]
            frame = names[result.frame_id] = f"{result.frame_id} ({name})"
            match = names.get(result.match_frame_id, str(result.match_frame_id))
            if result.status == place_pb2.LOOP_STATUS_LOOP_DETECTED:
                evidence = result.evidence
                loops += 1
                print(f"frame {frame} closes a loop with frame {match}: {result.inliers} "
                      f"inliers, spread {evidence.spread:.2f}, confirmations "
                      f"{evidence.confirmations}", flush=True)
            elif result.status == place_pb2.LOOP_STATUS_CANDIDATE:
                # A loop awaiting the next keyframes' confirmation: shown, not acted on.
                candidates += 1
                print(f"frame {frame}: candidate loop with frame {match}, awaiting "
                      "confirmation", flush=True)
    except Unavailable as error:
        return fail(f"cannot reach recogd at {client.target} ({error.details}): start it with "
                    "`bash scripts/run.sh` from the repository's root, or give the address of "
                    "a running one with --server or RECOG_SERVER")
    except RecogError as error:
        return fail(str(error))
    except OSError as error:  # an image that cannot be read
        return fail(str(error))
    finally:
        if client is not None:
            client.close()
    summary = (f"{plural(len(images), 'frame')} streamed into map {arguments.map!r}, "
               f"{plural(loops, 'loop')}")
    if candidates:
        summary += f", {plural(candidates, 'candidate')}"
    print(summary + (f" ({failed} not added)" if failed else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
