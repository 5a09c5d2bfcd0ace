"""Streams a folder of numbered images (tests/data/corridor) into a new place map and prints each
loop as `query match` file names. The map detects loops as `recog eval place --params` does with
`temporal_matches: 0` and `recent_frames: 1` (a loop needs no consistent previous queries)."""
import sys
from pathlib import Path

from recog_client import RecognitionClient, place_pb2

images = sorted(Path(sys.argv[1]).glob("*.jpg"), key=lambda path: int(path.stem))
settings = {"temporal_matches": 0, "recent_frames": 1}
with RecognitionClient() as client:  # the server: RECOG_SERVER, else 127.0.0.1:50051
    for answer in client.stream_frames("corridor", images, settings=settings):
        if answer.result.status == place_pb2.LOOP_STATUS_LOOP_DETECTED:
            print(images[answer.sequence].name, images[answer.result.match_frame_id].name)
