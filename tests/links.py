"""Helpers of the tests of `gcs.transport.link` on real loopback UDP: what a link hears."""

from __future__ import annotations

import selectors
import time

from gcs.transport.link import Link


def drain(link: Link, until, seconds: float = 5.0) -> list:
    """Receive until `until(messages so far)` holds or the deadline passes (no sleeping)."""
    selector = selectors.DefaultSelector()
    selector.register(link.fileno(), selectors.EVENT_READ)
    got: list = []
    deadline = time.monotonic() + seconds
    try:
        while not until(got) and time.monotonic() < deadline:
            if selector.select(0.05):
                got += link.receive(time.monotonic())
    finally:
        selector.close()
    return got
