"""What both ends of the fleet's MAVLink wire agree on, written once for `gcs` and `vehicles`.

`fleetwire.signing`: MAVLink 2 signing and the fleet key file; `fleetwire.messages`: the
fleet's identities, message names and encodings; `fleetwire.modes`: autopilot mode numbers,
from pymavlink's own maps; `fleetwire.geodesy`: the local ENU frame <-> WGS84. Imports
pymavlink only, and numpy and pymap3d for the geodesy (never `gcs`, `vehicles` or `planner`).
"""

import os

# The fleet speaks MAVLink 2 (signing needs it): pymavlink's mavutil reads this once, when it is
# first imported, to pick its dialect; `fleetwire.modes` imports it.
os.environ.setdefault("MAVLINK20", "1")
