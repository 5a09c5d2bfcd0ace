"""Streams a folder of images into a new place map of recogd and prints each loop it finds.

Each loop is one line `QUERY revisits MATCH` (file names), as the frame is answered; the last
line sums up. From the repository's root, with recogd running (`bash scripts/run.sh`) and the
package installed (client/python/README.md; or PYTHONPATH=build/python /usr/bin/python3)::

    $ .venv/bin/python client/python/examples/stream_corridor.py tests/data/corridor temporal_matches=0 recent_frames=1
    41.jpg revisits 1.jpg
    60.jpg revisits 20.jpg
    4 frames, 2 loops

KEY=VALUE arguments after the folder are the new map's settings (the MapSettings fields,
as `recog eval place --params` takes them); without any, the server's defaults, which find no
loop in a folder of recent_frames (20) frames or fewer: a frame's match must be more than that
many frames older. The images (.jpg, .jpeg, .png) go in natural order of their names (2.jpg
before 10.jpg). The server is --server, else RECOG_SERVER, else 127.0.0.1:50051. Exit status:
0 when the folder was streamed, 1 on an error (one line on stderr), 2 on a bad command line.

Or a bag's image topic instead of the folder, ``--bag BAG --topic T`` (then the settings): a ROS 1
bag, an MCAP file, a rosbag2 sqlite3 file or a rosbag2 folder, read by the project's CLI
(``recog bag extract``, see bag_frames.py; the binary is --recog, else RECOG_BIN, else recog on
PATH, else the checkout's build/bin/recog). Its frames go in the order of their header stamps,
each stamp the frame's timestamp: the map's tau_c then counts seconds (recent_seconds, 20 s by
default), and a frame is named by its stamp (`stamp 1002.000 revisits stamp 1000.000`).
"""

import argparse
import re
import statistics
import sys
from pathlib import Path

import bag_frames  # next to this file: the bag's frames through `recog bag extract`

try:
    from google.protobuf import json_format
    from recog_client import (AlreadyExists, RecogError, RecognitionClient, Unavailable,
                              make_frame, place_pb2)
except ModuleNotFoundError as missing:  # not the interpreter of the client's environment
    sys.exit(f"stream_corridor: {sys.executable} has no module {missing.name}: run this with "
             ".venv/bin/python (client/python/README.md, Installing) or, without installing, "
             "PYTHONPATH=build/python /usr/bin/python3")

PROGRAM = "stream_corridor"
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png"}


def natural_key(path: Path) -> list:
    """Sort key comparing the digit runs of a file name as numbers: "2.jpg" < "10.jpg"."""
    return [int(part) if part.isdigit() else part.lower()
            for part in re.split(r"(\d+)", path.name)]


def setting(text: str) -> tuple[str, object]:
    """One KEY=VALUE argument, checked against MapSettings (an argparse type)."""
    key, equals, value = text.partition("=")
    field = {key: {"true": True, "false": False}.get(value, value)}
    try:
        if not equals:
            raise ValueError("expected KEY=VALUE")
        json_format.ParseDict(field, place_pb2.MapSettings())
    except (ValueError, json_format.Error) as error:
        raise argparse.ArgumentTypeError(f"{text}: {str(error).splitlines()[0]}") from error
    return next(iter(field.items()))


def parse_arguments() -> argparse.Namespace:
    """Reads the command line; prints the usage and exits with 2 when it is wrong."""
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n", 1)[0],
        epilog="example: %(prog)s tests/data/corridor temporal_matches=0 recent_frames=1")
    parser.add_argument("--server", help="recogd's address (default: RECOG_SERVER, else "
                        "127.0.0.1:50051)")
    parser.add_argument("--map", default="corridor",
                        help="name of the new map (default: %(default)s; it must not exist)")
    parser.add_argument("folder", nargs="?", help="folder of the images (or --bag)")
    parser.add_argument("settings", nargs="*", type=setting, default=[], metavar="KEY=VALUE",
                        help="the new map's settings, e.g. temporal_matches=0 recent_frames=1 "
                        "(default: the server's)")
    parser.add_argument("--bag", type=Path, help="a bag instead of the folder: ROS 1, MCAP, "
                        "rosbag2 sqlite3 file or folder (read by `recog bag extract`)")
    parser.add_argument("--topic", help="with --bag: its image topic (without: the error lists "
                        "them)")
    parser.add_argument("--recog", help="with --bag: the recog binary that reads it (default: "
                        "RECOG_BIN, else recog on PATH, else the checkout's build/bin/recog)")
    arguments = parser.parse_intermixed_args()  # options may come after the settings too
    if arguments.bag is None:
        if arguments.folder is None:
            parser.error("the following arguments are required: folder (or --bag BAG --topic "
                         "TOPIC)")
        for option in ("topic", "recog"):
            if getattr(arguments, option):
                parser.error(f"--{option} goes with --bag")
    elif arguments.folder is not None:  # the first setting, taken for a folder
        if "=" not in arguments.folder:
            parser.error("give either a folder of images or --bag BAG --topic TOPIC")
        try:
            arguments.settings.insert(0, setting(arguments.folder))
        except argparse.ArgumentTypeError as error:
            parser.error(f"argument KEY=VALUE: {error}")
        arguments.folder = None
    if arguments.folder is not None:
        arguments.folder = Path(arguments.folder)
    return arguments


def fail(message: str) -> int:
    """Prints ``message`` as the program's one line on stderr; the exit status 1."""
    print(f"{PROGRAM}: {message}", file=sys.stderr)
    return 1


def plural(count: int, noun: str) -> str:
    """``count`` and ``noun``, with an s unless it is one."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def main() -> int:
    """Streams the folder or the bag; returns the exit status."""
    arguments = parse_arguments()
    settings = json_format.ParseDict(dict(arguments.settings), place_pb2.MapSettings())
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
            return stream(arguments, settings, images,
                          [f"stamp {frame.stamp:.3f}" for frame in bag.frames],
                          [frame.stamp for frame in bag.frames])
    folder = arguments.folder
    if not folder.is_dir():
        return fail(f"{folder}: no such folder")
    images = sorted((path for path in folder.iterdir()
                     if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES), key=natural_key)
    if not images:
        return fail(f"{folder}: no .jpg, .jpeg or .png image in it")
    return stream(arguments, settings, images, [path.name for path in images])


def stream(arguments: argparse.Namespace, settings: place_pb2.MapSettings, images,
           labels: list[str], stamps: list[float] | None = None) -> int:
    """Creates the map with ``settings``, streams ``images`` (one per label; ``stamps``, their
    timestamps, for a bag) into it, prints its loops and the summary; returns the exit status."""
    names = {}  # frame id in the map -> file name
    loops = failed = 0
    client = None
    try:
        client = RecognitionClient(arguments.server)
        settings = client.create_map(arguments.map, settings).settings  # every field: effective
        for answer in client.stream_frames(arguments.map, images, create_if_missing=False):
            name = labels[answer.sequence]
            if answer.HasField("error"):  # this frame only (e.g. not an image); the rest go on
                failed += 1
                print(f"{name}: not added: {answer.error.message}", file=sys.stderr)
                continue
            names[answer.result.frame_id] = name
            if answer.result.status == place_pb2.LOOP_STATUS_LOOP_DETECTED:
                loops += 1
                match = answer.result.match_frame_id
                print(f"{name} revisits {names.get(match, f'frame {match}')}", flush=True)
    except AlreadyExists:
        return fail(f"map '{arguments.map}' already exists on {client.target} (an earlier run?): "
                    "name a new one with --map, or delete it: "
                    f"build/bin/recog maps delete {arguments.map} --server {client.target}")
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

    summary = f"{plural(len(labels), 'frame')}, {plural(loops, 'loop')}"
    print(summary + (f" ({failed} not added)" if failed else ""))
    if stamps is not None:
        if not loops and len(stamps) > 1 and stamps[-1] - stamps[0] <= settings.recent_seconds:
            period = statistics.median(b - a for a, b in zip(stamps, stamps[1:]))
            print(f"{PROGRAM}: no loop can be found in a bag of {stamps[-1] - stamps[0]:g} s with "
                  f"recent_seconds={settings.recent_seconds:g} (a frame's match must be more "
                  f"than {settings.recent_seconds:g} s older); try temporal_matches=0 "
                  f"recent_seconds={1.5 * period:.3g}", file=sys.stderr)
    elif not loops and len(labels) <= settings.recent_frames:
        print(f"{PROGRAM}: no loop can be found in {len(labels)} frames with recent_frames="
              f"{settings.recent_frames} (a frame's match must be more than "
              f"{settings.recent_frames} frames older); try temporal_matches=0 recent_frames=1",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
