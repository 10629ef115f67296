"""The ground station's transport: MAVLink links for every connection string (`link`), the
fleet's signing (`signing`) and the `--out` outputs that copy every UAV's messages to other
tools (`forward`)."""
