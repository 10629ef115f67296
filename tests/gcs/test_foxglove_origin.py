"""Who may open the live Foxglove port from a browser (gcs.recording.foxglove_front): the `Origin`
of the upgrade request, on request heads alone (the port itself: test_run_recording.py)."""

from __future__ import annotations

import pytest

from gcs.recording.foxglove_front import refused_origin


def head(origin: str | None) -> bytes:
    lines = ["GET / HTTP/1.1", "Host: 127.0.0.1:8765", "Upgrade: websocket"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


@pytest.mark.parametrize(
    "origin",
    [None, "http://localhost:8080", "https://127.0.0.1", "http://[::1]:3000", "null", "file://"],
)
def test_local_file_and_originless_clients_may_connect(origin):
    assert refused_origin(head(origin)) is None


@pytest.mark.parametrize(
    "origin",
    ["https://evil.example", "http://localhost.evil.example", "https://app.foxglove.dev",
     "http://192.168.1.5:8080", "javascript:alert(1)"],
)  # fmt: skip
def test_any_other_page_is_refused(origin):
    assert refused_origin(head(origin)) == origin


def test_an_allowed_origin_connects_whatever_its_case_or_slash():
    allowed = ("https://app.foxglove.dev/",)
    assert refused_origin(head("https://APP.foxglove.dev"), allowed) is None
    assert refused_origin(head("https://app.foxglove.dev.evil.example"), allowed) is not None
