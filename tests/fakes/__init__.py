"""Scripted fake autopilots (ArduCopter, PX4) for the drivers' conformance tests.

Each fake is a pure state machine (`ArduCopterModel`, `Px4Model`: messages in, messages out,
time passed in) reproducing what the recorded SITL sessions in `tests/sitl/` show, plus a
`FakeEndpoint` that runs a model on a real UDP socket on loopback, speaking MAVLink 2 through
pymavlink, in a thread of the test process.
"""
