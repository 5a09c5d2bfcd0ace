"""A recogd process for the Python client tests: a free loopback port, a fresh data directory,
a wait until it serves and a stop that checks its exit status. The binary is RECOGD's."""

import os
import signal
import socket
import subprocess
import tempfile
from typing import Sequence

from recog_client import RecognitionClient, Unavailable
from waiting import wait_until

STARTUP_SECONDS = 30
SHUTDOWN_SECONDS = 30


def free_port() -> int:
    """A free loopback port (bound, read, released: another process may take it, rarely)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Recogd:
    """A recogd process on a free loopback port with a fresh data directory and ``args``."""

    def __init__(self, args: Sequence[str] = ()):
        recogd = os.environ.get("RECOGD")
        if not recogd:
            raise RuntimeError("set RECOGD to the path of the recogd binary")
        self.data_dir = tempfile.TemporaryDirectory(prefix="recog-python-test-")
        self.target = f"127.0.0.1:{free_port()}"  # the test certificate names 127.0.0.1
        self.process = subprocess.Popen([recogd, "--listen", self.target, "--data-dir",
                                         self.data_dir.name, "--metrics-listen", "",
                                         "--log-level", "warn", *args])

    def wait_until_serving(self, **client_options) -> None:
        """Polls list_maps until it stops answering UNAVAILABLE (at most STARTUP_SECONDS), each
        time from a new client with ``client_options`` (a channel that failed to connect waits
        out a growing backoff); stops the server and raises when it does not come up."""

        def serving() -> bool:
            if self.process.poll() is not None:
                raise RuntimeError(f"recogd exited with {self.process.returncode} at start-up")
            try:
                with RecognitionClient(self.target, **client_options) as probe:
                    list(probe.list_maps())
                return True
            except Unavailable:
                return False

        try:
            wait_until(serving, f"recogd serving on {self.target}", timeout=STARTUP_SECONDS,
                       interval=0.1)
        except BaseException:
            self.process.kill()
            self.process.wait()
            self.data_dir.cleanup()
            raise

    def stop(self) -> None:
        """Stops recogd with SIGTERM and checks that it exits with 0."""
        self.process.send_signal(signal.SIGTERM)
        try:
            code = self.process.wait(timeout=SHUTDOWN_SECONDS)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise AssertionError(f"recogd did not stop within {SHUTDOWN_SECONDS} s of SIGTERM")
        finally:
            self.data_dir.cleanup()
        if code != 0:
            raise AssertionError(f"recogd exited with {code} after SIGTERM")
