"""Mission texts shared by the tests of mission files, and the origin they place maps at."""

from __future__ import annotations

from gcs.geodesy import Origin

MINIMAL = """\
version: 1
start: {x: 0, y: 0}
goal: {x: 300, y: 100}
safety_margin: 5
radio_range: 120
altitude: 30
speed: {max: 8}
"""

LYON = Origin(lat=45.7640, lon=4.8357, alt=170.0)
