"""Streams a folder of numbered images into a new place map and prints each loop as `query match`
file names. Optional KEY=VALUE arguments are the map's settings (MapSettings fields, integers or
floats), as `recog eval place --params` takes them; without any, the server's defaults."""
import sys
from pathlib import Path

from recog_client import RecognitionClient, place_pb2

images = sorted(Path(sys.argv[1]).glob("*.jpg"), key=lambda path: int(path.stem))
settings = {k: float(v) if "." in v else int(v) for k, v in (a.split("=") for a in sys.argv[2:])}
with RecognitionClient() as client:  # the server: RECOG_SERVER, else 127.0.0.1:50051
    for answer in client.stream_frames("corridor", images, settings=settings):
        if answer.result.status == place_pb2.LOOP_STATUS_LOOP_DETECTED:
            print(images[answer.sequence].name, images[answer.result.match_frame_id].name)
