"""Streams a folder of images into a place map and prints each loop closure as it happens.

The images (.jpg, .jpeg, .png) are sent in natural order of their names (2.jpg before 10.jpg);
the map is created with the server's default settings when it does not exist. Example::

    .venv/bin/python client/python/examples/stream_folder.py --map corridor tests/data/corridor

(with the package installed, see client/python/README.md; or PYTHONPATH=build/python).
"""

import argparse
import re
import sys
from pathlib import Path

from recog_client import RecogError, RecognitionClient, place_pb2

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
    parser.add_argument("images", type=Path, help="folder of the images")
    return parser.parse_args()


def main() -> int:
    """Streams the folder; returns the exit status (1 when the stream failed)."""
    arguments = parse_arguments()
    images = list_images(arguments.images)
    if not images:
        print(f"stream_folder: no images in {arguments.images}", file=sys.stderr)
        return 1
    loops = 0
    with RecognitionClient(arguments.server, token_file=arguments.token_file) as client:
        try:
            for response in client.stream_frames(arguments.map, images):
                if response.HasField("error"):
                    print(f"{images[response.sequence].name}: error {response.error.code}: "
                          f"{response.error.message}", file=sys.stderr)
                elif response.result.status == place_pb2.LOOP_STATUS_LOOP_DETECTED:
                    result = response.result
                    evidence = result.evidence
                    loops += 1
                    print(f"frame {result.frame_id} closes a loop with frame "
                          f"{result.match_frame_id} (inliers {result.inliers}, spread "
                          f"{evidence.spread:.2f}, confirmations {evidence.confirmations})",
                          flush=True)
                elif response.result.status == place_pb2.LOOP_STATUS_CANDIDATE:
                    # A loop awaiting the next keyframes' confirmation: shown, not acted on.
                    result = response.result
                    print(f"frame {result.frame_id}: candidate loop with frame "
                          f"{result.match_frame_id}, awaiting confirmation", flush=True)
        except RecogError as error:
            print(f"stream_folder: {error}", file=sys.stderr)
            return 1
    print(f"streamed {len(images)} images into map {arguments.map!r}: {loops} loop closures")
    return 0


if __name__ == "__main__":
    sys.exit(main())
