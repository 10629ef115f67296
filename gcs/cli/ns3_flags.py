"""What the ns-3 commands share (`gcs log netsim`, `gcs eval paper --network ns3`, `gcs eval
calibrate`): the flags that say how ns-3 simulates, the `NetOptions` they make, and loading
ns-3 with its one-line refusal when the extra is missing."""

from __future__ import annotations

import argparse
import sys

from gcs.errors import InputError


def add_ns3_options(parser: argparse.ArgumentParser) -> None:
    """--seed, --propagation, --routing: how ns-3 simulates (`gcs.netsim.ns3.NetOptions`)."""
    parser.add_argument("--seed", type=int, default=1, metavar="N",
                        help="ns-3 run number and data phases (default 1)")  # fmt: skip
    parser.add_argument("--propagation", choices=("range", "logdistance"), default="range",
                        help="range: the paper's disk of rho_R (default); logdistance: "
                        "log-distance loss, 802.11b sensitivity at rho_R")  # fmt: skip
    parser.add_argument("--routing", choices=("aodv", "olsr"), default="aodv",
                        help="routing protocol (default aodv, hello 1 s)")  # fmt: skip


def ns3_options(args: argparse.Namespace):
    """The `NetOptions` of the flags of `add_ns3_options` (a bad --seed: exit 2)."""
    from gcs.netsim.ns3 import NetOptions

    if args.seed < 1:
        raise InputError(None, "--seed", f"an integer >= 1, got {args.seed}")
    return NetOptions(seed=args.seed, propagation=args.propagation, routing=args.routing)


def ns3_loaded() -> bool:
    """Load ns-3 (once per process); without the ns3 extra print its one line on stderr and
    return False (the command then exits 2)."""
    from gcs.netsim.ns3 import NetsimUnavailable, load_ns3

    try:
        load_ns3()
    except NetsimUnavailable as missing:
        print(missing, file=sys.stderr)
        return False
    return True
