"""Flight logs: the MCAP recorder (`recording`) and its scene (`scene`), reading a recording
back (`logreader`), the report (`report`), replay over MAVLink (`replay`) and the Foxglove
layout (`layout`)."""
