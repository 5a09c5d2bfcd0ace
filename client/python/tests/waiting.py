"""wait_until: how the Python client's tests wait for something a server or another thread does
(a server that serves, bytes the server kept) instead of sleeping a guessed time. It polls a
condition until it holds or a deadline passes, and then fails saying what did not happen. The
default deadline is generous (a sanitizer build on a loaded machine is slow): a wait that succeeds
returns as soon as the condition holds."""

import time
from typing import Callable, TypeVar

EVENT_TIMEOUT_SECONDS = 60.0

T = TypeVar("T")


def wait_until(condition: Callable[[], T], what: str, timeout: float = EVENT_TIMEOUT_SECONDS,
               interval: float = 0.05) -> T:
    """Calls ``condition`` every ``interval`` seconds until it returns a true value, and returns
    that; raises AssertionError("<what> did not happen within <timeout> s") at the deadline."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        if time.monotonic() >= deadline:
            raise AssertionError(f"{what} did not happen within {timeout:g} s")
        time.sleep(interval)
