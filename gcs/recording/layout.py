"""The Foxglove layout we ship (`layouts/fleetline-layout.json`), built with `foxglove.layouts`.

Left: the Map panel (each UAV's reported fix and its setpoint track, building footprints and
the planned path from the GeoJSON layers) above the 3-D panel (`/scene` over `/tf`: obstacles,
margins, path, rows, stations, UAVs, their virtual targets with a rho_c ring, radio links).
Right: tracking error per UAV (one series per array index of `/metrics.tracking_error_m`, so
the layout fits any fleet size), the instant's smallest UAV-UAV and UAV-obstacle distances
(`/fleet`), the formation's speed, and the event log.

`python -m gcs.recording.layout` rewrites the committed file; `--check` exits 1 if it is stale.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import foxglove.layouts as fl

from gcs.recording.scene import MAP_FRAME, uav_colour

#: Where the layout is committed.
LAYOUT_PATH = Path(__file__).resolve().parents[2] / "layouts" / "fleetline-layout.json"
#: Map topics are given colours for this many UAVs (more UAVs still show, in the default).
COLOURED_UAVS = 10


def build_layout() -> fl.Layout:
    """The fleetline layout (see the module docstring)."""

    topic_config = {
        "/map/obstacles": fl.MapTopicSettings(history_mode="previous"),
        "/map/plan": fl.MapTopicSettings(history_mode="previous"),
    }
    colours = {"/map/obstacles": "#555555", "/map/plan": "#ff8c00"}
    for uav in range(1, COLOURED_UAVS + 1):
        colours[f"/uav{uav}/fix"] = uav_colour(uav)
        colours[f"/uav{uav}/target"] = "#9e9e9e"
        topic_config[f"/uav{uav}/fix"] = fl.MapTopicSettings(
            history_mode="all", point_display_mode="dot", point_size=4
        )
        topic_config[f"/uav{uav}/target"] = fl.MapTopicSettings(
            history_mode="all", point_display_mode="dot", point_size=2
        )
    map_panel = fl.MapPanel(
        title="Map: fixes (colour), setpoints (grey), buildings, planned path",
        config=fl.MapConfig(
            layer="map",
            zoom_level=17,
            follow_topic="/uav1/fix",
            topic_colors=colours,
            topic_config=topic_config,
        ),
    )
    scene_panel = fl.ThreeDeePanel(
        title="3-D: obstacles, margins, path, UAVs, targets (rho_c rings), radio links",
        config=fl.ThreeDeeConfig(
            fixed_frame=MAP_FRAME,
            follow_tf=MAP_FRAME,
            camera_state=fl.ThreeDeeCameraState(
                distance=450.0, perspective=True, phi=50.0, theta_offset=45.0, far=20000.0
            ),
            topics={
                "/scene": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
            },
        ),
    )
    tracking = fl.PlotPanel(
        title="Tracking error |R_n - V_n| per UAV (m), must stay < rho_c",
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(
                    value="/metrics.tracking_error_m",
                    array_expansion="byIndex",
                    label="UAV index",
                ),
                fl.PlotSeries(
                    value="/metrics.max_tracking_error_m",
                    label="max so far",
                    line_style="dashed",
                    color="#d62728",
                ),
            ],
            show_legend=True,
            y_axis_label="m",
            min_y_value=0,
        ),
    )
    distances = fl.PlotPanel(
        title=(
            "Smallest distances now (m), > 0 by design: UAV-UAV (targets keep 2 rho_c), "
            "UAV-obstacle (targets keep rho_c)"
        ),
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(value="/fleet.uav_uav_m", label="UAV-UAV", color="#1f77b4"),
                fl.PlotSeries(value="/fleet.uav_obstacle_m", label="UAV-obstacle", color="#ff7f0e"),
            ],
            show_legend=True,
            y_axis_label="m",
            min_y_value=0,
        ),
    )
    speed = fl.PlotPanel(
        title="Formation speed (m/s) and radio links",
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(
                    value="/metrics.formation_speed",
                    label="formation speed",
                    line_interpolation="step",
                ),
                fl.PlotSeries(
                    value="/fleet.radio_links",
                    label="radio links",
                    line_interpolation="step",
                    line_style="dotted",
                ),
            ],
            show_legend=True,
        ),
    )
    events = fl.LogPanel(title="Events", config=fl.LogConfig(topic_to_render="/events"))
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(
                    proportion=3,
                    content=fl.SplitContainer(
                        direction="column",
                        items=[
                            fl.SplitItem(proportion=1, content=map_panel),
                            fl.SplitItem(proportion=1, content=scene_panel),
                        ],
                    ),
                ),
                fl.SplitItem(
                    proportion=2,
                    content=fl.SplitContainer(
                        direction="column",
                        items=[
                            fl.SplitItem(proportion=1, content=tracking),
                            fl.SplitItem(proportion=1, content=distances),
                            fl.SplitItem(proportion=1, content=speed),
                            fl.SplitItem(proportion=1, content=events),
                        ],
                    ),
                ),
            ],
        )
    )


def layout_text() -> str:
    """The layout as the committed file holds it (indented JSON, one trailing newline)."""
    return json.dumps(json.loads(build_layout().to_json()), indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m gcs.recording.layout", description="Write (or check) the Foxglove layout."
    )
    parser.add_argument("--out", type=Path, default=LAYOUT_PATH, help="file to write")
    parser.add_argument("--check", action="store_true", help="exit 1 if the file is stale")
    args = parser.parse_args(argv)
    text = layout_text()
    if args.check:
        current = args.out.read_text() if args.out.exists() else ""
        if current != text:
            print(f"{args.out} is stale: run python -m gcs.recording.layout", file=sys.stderr)
            return 1
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
