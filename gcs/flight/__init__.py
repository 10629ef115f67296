"""Flying a mission: the ground-station core (`core`), its clocks (`clock`) and the live loop
over real links (`live`); the fast mode (`gcs.sim.fastsim`) drives the same core in lockstep."""
