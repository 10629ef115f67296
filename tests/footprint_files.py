"""Footprint files (GeoJSON) shared by the tests of maps and of recordings."""

from __future__ import annotations

#: A footprint file at origin 0, 0: a Point (no footprint) and a small polygon, about 14 m x 11 m,
#: 20-35 m west of the origin.
MESSY = {
    "type": "FeatureCollection",
    "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [0, 0]}},
        {
            "type": "Feature",
            "properties": {},
            "geometry": {
                "type": "Polygon",
                "coordinates": [
                    [
                        [-0.00031, -0.00005],
                        [-0.00018, -0.00005],
                        [-0.00018, 0.00005],
                        [-0.00031, 0.00005],
                        [-0.00031, -0.00005],
                    ]
                ],
            },
        },
    ],
}
