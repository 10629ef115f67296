"""End-to-end flights: real processes over UDP on loopback (all marked slow)."""
