"""The simulated radio medium between the ground station and the vehicles: the multi-hop radio
model (`medium.radio`), its counters (`medium.radio_stats`), ground users (`medium.ground_users`),
the medium itself (`medium.medium`: `MediumModel` and the socket process) and its command line
(`python -m medium.cli`)."""
