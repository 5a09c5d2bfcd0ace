"""Streams a folder of images into a place map and prints each loop closure as it happens.

The images (.jpg, .jpeg, .png) are sent in natural order of their names (2.jpg before 10.jpg);
the map is created with the server's default settings when it does not exist, and a map that
exists gets the frames after its own. The last line sums up, e.g.
`4 frames streamed into map 'lab', 0 loops`. Example::

    .venv/bin/python client/python/examples/stream_folder.py --map corridor tests/data/corridor

(with the package installed, see client/python/README.md; or PYTHONPATH=build/python). Exit
status: 0 when the folder was streamed, 1 on an error (one line on stderr), 2 on a bad command
line.

Or a bag's image topic instead of the folder (``--bag BAG --topic T``): a ROS 1 bag, an MCAP
file, a rosbag2 sqlite3 file or a rosbag2 folder, read by the project's CLI (``recog bag
extract``, see bag_frames.py; the binary is --recog, else RECOG_BIN, else recog on PATH, else
the checkout's build/bin/recog). sensor_msgs/Image (sent as lossless PNG) or
sensor_msgs/CompressedImage (its JPEG or PNG bytes), in the order of their header stamps, each
stamp the frame's timestamp (the map's tau_c then counts seconds: recent_seconds). Without
--topic, the error lists the bag's image topics.
"""

import argparse
import re
import sys
from pathlib import Path

import bag_frames  # next to this file: the bag's frames through `recog bag extract`

try:
    from recog_client import RecogError, RecognitionClient, Unavailable, make_frame, place_pb2
except ModuleNotFoundError as missing:  # not the interpreter of the client's environment
    sys.exit(f"stream_folder: {sys.executable} has no module {missing.name}: run this with "
             ".venv/bin/python (client/python/README.md, Installing) or, without installing, "
             "PYTHONPATH=build/python /usr/bin/python3")

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png"}


def natural_key(name: str) -> list:
    """Sort key comparing the digit runs of a name as numbers: "2.jpg" < "10.jpg"."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def list_images(folder: Path) -> list[Path]:
    """Returns the images directly in ``folder``, in natural order of their names."""
    images = [path for path in folder.iterdir()
              if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(images, key=lambda path: natural_key(path.name))


def parse_arguments() -> argparse.Namespace:
    """Reads the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--server", help="recogd's host:port (default: RECOG_SERVER, else "
                        "127.0.0.1:50051)")
    parser.add_argument("--map", required=True, help="name of the map to stream into")
    parser.add_argument("--token-file", help="file of the bearer token, when the server has "
                        "tokens (default: RECOG_TOKEN_FILE)")
    parser.add_argument("images", type=Path, nargs="?", help="folder of the images")
    parser.add_argument("--bag", type=Path, help="a bag instead of the folder: ROS 1, MCAP, "
                        "rosbag2 sqlite3 file or folder (read by `recog bag extract`)")
    parser.add_argument("--topic", help="with --bag: its image topic (without: the error lists "
                        "them)")
    parser.add_argument("--recog", help="with --bag: the recog binary that reads it (default: "
                        "RECOG_BIN, else recog on PATH, else the checkout's build/bin/recog)")
    arguments = parser.parse_args()
    if (arguments.images is None) == (arguments.bag is None):
        parser.error("give either a folder of images or --bag BAG --topic TOPIC")
    for option in ("topic", "recog"):
        if getattr(arguments, option) and not arguments.bag:
            parser.error(f"--{option} goes with --bag")
    return arguments


def fail(message: str) -> int:
    """Prints ``message`` as the program's one line on stderr; the exit status 1."""
    print(f"stream_folder: {message}", file=sys.stderr)
    return 1


def plural(count: int, noun: str) -> str:
    """``count`` and ``noun``, with an s unless it is one."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def main() -> int:
    """Streams the folder or the bag; returns the exit status (1 when the stream failed)."""
    arguments = parse_arguments()
    if arguments.bag:
        try:
            bag = bag_frames.extract(arguments.bag, arguments.topic, arguments.recog)
        except bag_frames.BagError as error:
            return fail(str(error))
        with bag:  # the extracted images live until the stream ends
            if not bag.frames:
                return fail(f"{arguments.bag}: no message on {arguments.topic}")
            # Read one at a time, as the stream sends them.
            images = (make_frame(str(frame.path), timestamp=frame.stamp)
                      for frame in bag.frames)
            return stream(arguments, images, [f"stamp {frame.stamp:.3f}" for frame in bag.frames])
    if not arguments.images.is_dir():
        return fail(f"{arguments.images}: no such folder")
    images = list_images(arguments.images)
    if not images:
        return fail(f"{arguments.images}: no .jpg, .jpeg or .png image in it")
    return stream(arguments, images, [path.name for path in images])


def stream(arguments: argparse.Namespace, images, labels: list[str]) -> int:
    """Streams ``images`` (one per label) into the map and prints its loops and the summary;
    returns the exit status."""
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
    summary = (f"{plural(len(labels), 'frame')} streamed into map {arguments.map!r}, "
               f"{plural(loops, 'loop')}")
    if candidates:
        summary += f", {plural(candidates, 'candidate')}"
    print(summary + (f" ({failed} not added)" if failed else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
