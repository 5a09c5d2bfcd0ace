"""The frames of a robot recording's image topic for the examples, read by the project's CLI.

Any bag `recog` opens (by content, not by name): a ROS 1 bag, an MCAP file, a rosbag2 sqlite3
file or a rosbag2 folder (metadata.yaml and its files). ``extract`` runs
``recog bag extract BAG --topic T -o TMPDIR`` into a temporary folder and gives the frames in
header-stamp order, each a file (a CompressedImage's JPEG or PNG bytes as they are, a raw Image
as a lossless PNG, BGR or grey) and its header stamp in seconds, the frame's timestamp::

    with bag_frames.extract(Path("run.mcap"), "/camera/image_raw", recog=None) as bag:
        frames = (make_frame(str(f.path), timestamp=f.stamp) for f in bag.frames)

Why recog's reader and not one in Python: it is the one reader of the C++ tools (recog eval,
recog stream), for every kind of bag, tested against the MCAP conformance suite and fuzzed;
Debian has no Python package for MCAP or rosbag2, and one reader means one behaviour (the same
frames, stamps, conversions and errors) wherever a bag is read. The cost: the examples need the
``recog`` binary, found by :func:`find_recog`.

Only the standard library: the examples import this module from their own folder.
"""

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import NamedTuple

#: recog as the repository builds it (scripts/build.sh), when the examples run from a checkout.
CHECKOUT_RECOG = Path(__file__).resolve().parents[3] / "build" / "bin" / "recog"
#: The image types, as ROS 1 (sensor_msgs/Image) and ROS 2 (sensor_msgs/msg/Image) name them.
IMAGE_TYPES = {"sensor_msgs/Image", "sensor_msgs/CompressedImage",
               "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"}


class BagError(Exception):
    """A bag that cannot be streamed, or no recog to read it (its message is the example's one
    line)."""


class BagFrame(NamedTuple):
    """One frame of the topic: its image file (inside the extraction's temporary folder) and
    its header stamp in seconds."""
    path: Path
    stamp: float


class Extraction:
    """The frames of one topic, extracted into a temporary folder that lives until ``close()``
    (or the end of a ``with`` block)."""

    def __init__(self, folder: tempfile.TemporaryDirectory, frames: list[BagFrame]):
        self._folder = folder
        self.frames = frames

    def close(self) -> None:
        """Removes the temporary folder and its images."""
        self._folder.cleanup()

    def __enter__(self) -> "Extraction":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def find_recog(given: str | None = None) -> str:
    """The recog binary: ``given`` (an example's --recog), else RECOG_BIN, else ``recog`` on
    PATH, else the checkout's build/bin/recog; BagError saying how to get one."""
    for value, origin in ((given, "--recog"), (os.environ.get("RECOG_BIN"), "RECOG_BIN")):
        if value:  # named: it must be there, no other one is tried
            found = shutil.which(value)
            if found is None:
                raise BagError(f"{value} (from {origin}) is not an executable file: give the "
                               "path of recog, the project's CLI (build/bin/recog once built)")
            return found
    found = shutil.which("recog")
    if found is not None:
        return found
    if os.access(CHECKOUT_RECOG, os.X_OK) and CHECKOUT_RECOG.is_file():
        return str(CHECKOUT_RECOG)
    raise BagError(f"a bag is read by recog, the project's CLI, and there is none on PATH nor at "
                   f"{CHECKOUT_RECOG}: build it with `bash scripts/build.sh recog` from the "
                   "repository's root, or give its path with --recog or RECOG_BIN")


def _run(recog: str, command: str, *args: str) -> str:
    """Runs ``recog bag COMMAND ARGS``; its stdout, or BagError with its error line (recog's
    "recog bag COMMAND: CODE: message" without the program's name)."""
    try:
        answer = subprocess.run([recog, "bag", command, *args], capture_output=True, text=True,
                                check=False)
    except OSError as error:
        raise BagError(f"cannot run {recog}: {error.strerror or error}") from None
    if answer.returncode == 0:
        return answer.stdout
    prefix = f"recog bag {command}: "
    lines = [line for line in answer.stderr.splitlines() if line.strip()]
    for line in reversed(lines):
        if line.startswith(prefix):
            raise BagError(line[len(prefix):])
    status = (f"killed by signal {-answer.returncode}" if answer.returncode < 0
              else f"exit status {answer.returncode}")
    raise BagError(f"{recog} bag {command} failed ({status})"
                   + (f": {lines[-1]}" if lines else ""))


def image_topics(bag: Path, recog: str) -> list[str]:
    """The bag's image topics (sensor_msgs Image and CompressedImage), each as
    ``name (type, encoding WxH, N messages)``, from ``recog bag info --json``."""
    info = json.loads(_run(recog, "info", "--json", "--", str(bag)))
    topics = []
    for topic in sorted(info.get("topics", []), key=lambda topic: topic["name"]):
        if topic.get("type") not in IMAGE_TYPES:
            continue
        details = [topic["type"]]
        if topic.get("encoding"):
            size = (f" {topic['width']}x{topic['height']}" if topic.get("width") else "")
            details.append(topic["encoding"] + size)
        details.append(f"{topic.get('messages', 0)} messages")
        topics.append(f"{topic['name']} ({', '.join(details)})")
    return topics


def read_stamps(folder: Path) -> list[BagFrame]:
    """The frames listed in ``folder``/rgb.txt (TUM layout: '#' comment lines, then
    ``stamp path`` per frame, the path relative to ``folder``), in its order."""
    frames = []
    with open(folder / "rgb.txt", encoding="utf-8") as listing:
        for line in listing:
            if line.strip() and not line.startswith("#"):
                stamp, name = line.split(maxsplit=1)
                frames.append(BagFrame(folder / name.strip(), float(stamp)))
    return frames


def extract(bag: Path, topic: str | None, recog: str | None = None) -> Extraction:
    """The frames of ``topic`` in ``bag``, extracted by ``recog bag extract`` (``recog`` as
    :func:`find_recog` takes it) into a temporary folder, in header-stamp order. BagError, with
    nothing left behind, for: no recog, no ``topic`` (the message lists the bag's image
    topics), and recog's own errors (a missing file, not a bag, no such topic, a topic of
    another type, an encoding recog does not take, a damaged bag)."""
    program = find_recog(recog)
    if not topic:
        listed = image_topics(bag, program)
        raise BagError(f"{bag}: give --topic, one of its image topics: {', '.join(listed)}"
                       if listed else f"{bag}: it has no image topic (sensor_msgs Image or "
                       "CompressedImage)")
    folder = tempfile.TemporaryDirectory(prefix="recog-bag-")
    try:
        _run(program, "extract", f"--topic={topic}", "-o", folder.name, "--", str(bag))
        try:
            frames = read_stamps(Path(folder.name))
        except (OSError, ValueError) as error:  # not as recog writes it
            raise BagError(f"{bag}: recog bag extract's rgb.txt cannot be read: {error}") from None
    except BaseException:
        folder.cleanup()
        raise
    return Extraction(folder, frames)
