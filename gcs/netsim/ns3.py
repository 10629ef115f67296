"""Fly a `NetScenario` in ns-3 and measure its network (docs/netsim.md).

One ns-3 node per UAV (a `WaypointMobilityModel` fed with the 10 Hz samples, linear in
between), per base station and per ground user (fixed). Every node has one 802.11b ad hoc
interface (`AdhocWifiMac`, `ConstantRateWifiManager`: DsssRate11Mbps data, DsssRate1Mbps
control, `YansWifiChannel` with a constant-speed propagation delay) and runs the routing
protocol (AODV, hello every `hello_s`; or OLSR). The radio range:

* "range" (default): the paper's disk, `RangePropagationLossModel` with MaxRange = rho_R;
* "logdistance": `LogDistancePropagationLossModel` from 40.05 dB at 1 m (free space at
  2.412 GHz) with the exponent that brings the 16.02 dBm transmission down to the 802.11b
  11 Mbit/s receiver sensitivity, -76 dBm, at rho_R; the PHY's RxSensitivity is -76 dBm.

The distance is horizontal by default (`geometry="2d"`: every node at z = 0, the paper's
2-D disk and the planner's guarantee); `geometry="3d"` puts the UAVs at their flown height and
the fixed nodes on the ground.

Every node runs the routing protocol and relays, base stations and ground users too (the fast
mode's medium lets ground users relay nothing). ARP forgets a neighbour it failed to resolve
after `ARP_DEAD_S` (ns-3's default, 100 s, parts two UAVs for 100 s after one lost ARP
exchange whatever the routing protocol finds; Linux tries again with the next packet).

Traffic (C++ in `gcs.netsim._fleetnet`): each UAV and each ground user sends
`data_rate_bps` of UDP (`packet_bytes` of payload a packet, one packet every 8 x bytes / rate
s from a random phase) to its nearest base station at that instant: the one it reaches in the
fewest hops of the disk graph of rho_R, the closest of those on a tie, the closest of all when
it reaches none (`gcs.netsim.scenario.station_table`; the closest one is often out of reach
of the chain's tail). Each leader's speed request is relayed twice: the paper's way (one
unicast UDP packet per hop of the line: the leader to k+1 and k-1, each UAV on to the next)
and the ground station's way (leader -> its base station -> the ground station, wired to
every base station -> each UAV from that UAV's base station).

Determinism: ns-3's seed is 1 and its run number `seed` (`RngSeedManager`), every random
stream is assigned explicitly, and the data phases come from numpy's generator seeded with
`seed`: the same scenario and options give the same numbers, run after run in one process
(ns-3's simulator is destroyed and its address and stream counters reset between runs).
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError
from gcs.netsim.scenario import SAMPLE_HZ, NetScenario, station_table

PROPAGATIONS = ("range", "logdistance")
ROUTINGS = ("aodv", "olsr")
GEOMETRIES = ("2d", "3d")

#: Simulated seconds before the scenario's first sample (the routing protocol starts).
WARMUP_S = 1.0
#: Simulated seconds after the last sample for the packets in flight.
DRAIN_S = 5.0
#: UDP port of the data and relay packets.
PORT = 9
#: 802.11b at 11 Mbit/s: IEEE 802.11-2016 sec. 16.3.8.2 minimum input sensitivity (dBm).
RX_THRESHOLD_DBM = -76.0
#: ns-3's default transmission power (dBm) and loss at 1 m for "logdistance" (dB).
TX_POWER_DBM = 16.0206
REFERENCE_LOSS_DB = 40.05
#: How long ARP holds a neighbour it failed to resolve as dead (s; ns-3's default is 100 s,
#: Linux retries on the next packet): with 100 s one failed exchange between two UAVs parts
#: them for 100 s whatever the routing protocol finds (docs/netsim.md).
ARP_DEAD_S = 1.0
#: The message of `NetsimUnavailable`.
MISSING_EXTRA = "the ns3 extra is not installed: pip install 'fleetline[ns3]'"


class NetsimUnavailable(FleetlineError, RuntimeError):
    """ns-3's Python bindings cannot be imported."""

    exit_status = EXIT_BAD_INPUT

    def __init__(self, message: str = MISSING_EXTRA) -> None:
        super().__init__(message)


@dataclass(frozen=True)
class NetOptions:
    """How to simulate: `seed` (ns-3's run number and the data phases), `propagation`
    ("range" | "logdistance"), `routing` ("aodv" | "olsr"), `hello_s` (AODV's and OLSR's hello
    interval), `geometry` ("2d" | "3d", the distance of the range model), `wired_delay_s`
    (base station to ground station and back)."""

    seed: int = 1
    propagation: str = "range"
    routing: str = "aodv"
    hello_s: float = 1.0
    geometry: str = "2d"
    wired_delay_s: float = 0.0

    def __post_init__(self) -> None:
        if (
            not isinstance(self.seed, int | np.integer)
            or isinstance(self.seed, bool)
            or self.seed < 1
        ):
            raise ValueError(f"seed: expected an integer >= 1, got {self.seed!r}")
        if self.propagation not in PROPAGATIONS:
            raise ValueError(
                f"propagation: expected one of {PROPAGATIONS}, got {self.propagation!r}"
            )
        if self.routing not in ROUTINGS:
            raise ValueError(f"routing: expected one of {ROUTINGS}, got {self.routing!r}")
        if self.geometry not in GEOMETRIES:
            raise ValueError(f"geometry: expected one of {GEOMETRIES}, got {self.geometry!r}")
        if not (math.isfinite(self.hello_s) and self.hello_s > 0):
            raise ValueError(f"hello_s: expected a number > 0, got {self.hello_s}")
        if not (math.isfinite(self.wired_delay_s) and self.wired_delay_s >= 0):
            raise ValueError(f"wired_delay_s: expected a number >= 0, got {self.wired_delay_s}")


@dataclass(frozen=True, eq=False)
class NetResult:
    """What ns-3 measured (times are mission seconds; NaN: never).

    Per data packet (D,): `source_kind` "uav" | "user", `source_id` (1-based UAV or ground
    user number), `sent_s`, `received_s`, `hops` (-1: lost), `station` (0-based base station it
    was sent to, 0 = A). Per speed request (R,) and UAV (N): `paper_received_s` (R, N) by the
    paper's chain, `gcs_received_s` (R, N) by the ground station's relay (the leader's own
    cell: the time it sent it), with their hops (-1: never; the paper's chain: the radio hops
    of all its packets) and `paper_relays` (R, N) the chain's packets up to each UAV;
    `uplink_received_s` (R,) when the ground
    station had it. Wall-clock seconds: `import_s` (loading ns-3's bindings and compiling our
    C++, paid once per process: 0 when an earlier call did; `extra["import_s"]` has the first
    load's), `build_s` (nodes, devices, stacks, trajectories, schedules), `run_s`
    (Simulator::Run).
    """

    scenario: NetScenario
    options: NetOptions
    source_kind: np.ndarray
    source_id: np.ndarray
    sent_s: np.ndarray
    received_s: np.ndarray
    hops: np.ndarray
    station: np.ndarray
    paper_received_s: np.ndarray
    paper_hops: np.ndarray
    paper_relays: np.ndarray
    gcs_received_s: np.ndarray
    gcs_hops: np.ndarray
    uplink_received_s: np.ndarray
    uplink_hops: np.ndarray
    uplink_station: np.ndarray
    import_s: float
    build_s: float
    run_s: float
    extra: dict[str, Any] = field(default_factory=dict)

    # ----------------------------------------------------------------- summaries
    @property
    def delivered(self) -> np.ndarray:
        return np.isfinite(self.received_s)

    @property
    def delay_s(self) -> np.ndarray:
        """T_BS of each packet (NaN: lost)."""
        return self.received_s - self.sent_s

    def _mask(self, kind: str, source_id: int) -> np.ndarray:
        return (self.source_kind == kind) & (self.source_id == source_id)

    def source_summary(self, kind: str, source_id: int) -> dict[str, Any]:
        """Delivery ratio, T_BS and hops of one source's packets."""
        mask = self._mask(kind, source_id)
        delivered = mask & self.delivered
        delays = self.delay_s[delivered]
        hops = self.hops[delivered]
        sent = int(mask.sum())
        return {
            "kind": kind,
            "id": int(source_id),
            "sent": sent,
            "received": int(delivered.sum()),
            "delivery_ratio": float(delivered.sum() / sent) if sent else None,
            "t_bs_mean_s": _stat(delays, np.mean),
            "t_bs_p95_s": _stat(delays, lambda v: np.percentile(v, 95)),
            "t_bs_max_s": _stat(delays, np.max),
            "hops_mean": _stat(hops, np.mean),
            "hops_max": None if not hops.size else int(hops.max()),
            "hops_histogram": {
                str(h): int(c) for h, c in zip(*np.unique(hops, return_counts=True), strict=True)
            },
        }

    def delay_summary(self) -> dict[str, float | None]:
        """T_BS over every delivered packet: mean, p95, max (s)."""
        delays = self.delay_s[self.delivered]
        return {
            "mean_s": _stat(delays, np.mean),
            "p95_s": _stat(delays, lambda v: np.percentile(v, 95)),
            "max_s": _stat(delays, np.max),
        }

    def handover_gaps(self) -> np.ndarray:
        """(N,) per UAV: the longest interval (s) without one of its packets delivered while
        it flies (from its first to its last flying sample; NaN: it never flew)."""
        scenario = self.scenario
        flying = scenario.flying
        gaps = np.full(scenario.fleet_size, np.nan)
        for index in range(scenario.fleet_size):
            flown = scenario.times[flying[:, index]]
            if not flown.size:
                continue
            start, end = float(flown[0]), float(flown[-1])
            mask = self._mask("uav", index + 1) & self.delivered
            received = np.sort(self.received_s[mask])
            inside = received[(received > start) & (received < end)]
            gaps[index] = float(np.diff(np.concatenate([[start], inside, [end]])).max())
        return gaps

    def t_dv(self, relay: str) -> np.ndarray:
        """(R, N) T_dv (s): when each UAV received each request, counted from the time its
        leader sent it; `relay` "paper" (the chain) or "gcs" (through the ground station)."""
        received = {"paper": self.paper_received_s, "gcs": self.gcs_received_s}[relay]
        sent = np.array([r.t for r in self.scenario.requests], dtype=float).reshape(-1, 1)
        return received - sent

    def bs_con(self, bin_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """BS_con: (K,) bin starts (mission s) and (K, B) packets received per base station
        per second in each bin."""
        times = self.scenario.times
        edges = np.arange(times[0], times[-1] + DRAIN_S + bin_s, bin_s)
        stations = len(self.scenario.base_stations)
        counts = np.zeros((len(edges) - 1, stations))
        for s in range(stations):
            mask = self.delivered & (self.station == s)
            counts[:, s] = np.histogram(self.received_s[mask], edges)[0] / bin_s
        return edges[:-1], counts

    def per_uav(self) -> list[dict[str, Any]]:
        """One row per UAV: delivery, T_BS, hops, longest gap, worst T_dv of both relays."""
        gaps = self.handover_gaps()
        paper, gcs = self.t_dv("paper"), self.t_dv("gcs")
        rows = []
        for index in range(self.scenario.fleet_size):
            row = self.source_summary("uav", index + 1)
            row["longest_gap_s"] = _finite(gaps[index])
            row["t_dv_paper_worst_s"] = _worst(paper[:, index]) if len(paper) else None
            row["t_dv_gcs_worst_s"] = _worst(gcs[:, index]) if len(gcs) else None
            row["t_dv_paper_lost"] = int(np.isnan(paper[:, index]).sum())
            row["t_dv_gcs_lost"] = int(np.isnan(gcs[:, index]).sum())
            rows.append(row)
        return rows

    def to_json(self) -> dict:
        """Everything as strict JSON (NaN: null)."""
        users = len(self.scenario.ground_users)
        starts, counts = self.bs_con()
        requests = []
        paper, gcs = self.t_dv("paper"), self.t_dv("gcs")
        for r, request in enumerate(self.scenario.requests):
            requests.append(
                {
                    "t": request.t,
                    "leader": request.leader,
                    "t_dv_paper_s": _list(paper[r]),
                    "t_dv_gcs_s": _list(gcs[r]),
                    "paper_hops": self.paper_hops[r].astype(int).tolist(),
                    "paper_relays": self.paper_relays[r].astype(int).tolist(),
                    "gcs_hops": self.gcs_hops[r].astype(int).tolist(),
                    "uplink_s": _finite(self.uplink_received_s[r] - request.t),
                    "uplink_hops": int(self.uplink_hops[r]),
                    "uplink_station": int(self.uplink_station[r]),
                }
            )
        delivered = self.delivered
        return {
            "scenario": self.scenario.describe(),
            "options": asdict(self.options),
            "ns3": self.extra,
            "wall_s": {"import": self.import_s, "build": self.build_s, "run": self.run_s},
            "packets_sent": int(len(self.sent_s)),
            "packets_received": int(delivered.sum()),
            "delivery_ratio": float(delivered.mean()) if len(delivered) else None,
            "t_bs": self.delay_summary(),
            "uavs": self.per_uav(),
            "ground_users": [self.source_summary("user", k + 1) for k in range(users)],
            "requests": requests,
            "bs_con": {"bin_s": 1.0, "t": _list(starts), "per_second": counts.tolist()},
            "packets": {
                "source_kind": self.source_kind.tolist(),
                "source_id": self.source_id.astype(int).tolist(),
                "sent_s": _list(self.sent_s),
                "received_s": _list(self.received_s),
                "hops": self.hops.astype(int).tolist(),
                "station": self.station.astype(int).tolist(),
            },
        }


def _finite(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _list(values: np.ndarray) -> list[float | None]:
    return [_finite(v) for v in np.asarray(values, dtype=float).ravel()]


def _stat(values: np.ndarray, how) -> float | None:
    return float(how(values)) if values.size else None


def _worst(values: np.ndarray) -> float | None:
    """The largest of `values`, None when one is missing (never received) or none exist."""
    if not values.size or np.isnan(values).any():
        return None
    return float(values.max())


# --------------------------------------------------------------------------- ns-3
_NS = None
#: Wall seconds of the first import in this process: ns-3's bindings, then our C++.
IMPORT_TIMES: dict[str, float] = {}


def load_ns3():
    """ns-3's bindings with our C++ compiled in (once per process; ~10 s the first time);
    `NetsimUnavailable` without the ns3 extra."""
    global _NS
    if _NS is not None:
        return _NS
    from gcs.netsim._fleetnet import SOURCE

    with _quiet_cling():
        began = time.perf_counter()
        try:
            from ns import ns
        except (ImportError, SystemExit) as error:  # the `ns` stub exits without ns3
            raise NetsimUnavailable() from error
        IMPORT_TIMES["bindings_s"] = time.perf_counter() - began
        began = time.perf_counter()
        ns.cppyy.cppdef(SOURCE)
        IMPORT_TIMES["compile_s"] = time.perf_counter() - began
    _NS = ns
    return ns


#: What cppyy's interpreter prints on stderr while ns-3 loads, harmlessly.
_CLING_NOISE = "[runStaticInitializersOnce]: Failed to materialize symbols"


@contextlib.contextmanager
def _quiet_cling():
    """Run the block with file descriptor 2 in a temporary file, then copy what was written
    there back to stderr, without the lines of `_CLING_NOISE` (C++ writes to the descriptor,
    not to `sys.stderr`), nothing when ns-3 is missing."""
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no descriptor 2: nothing to filter
        yield
        return
    with tempfile.TemporaryFile(mode="w+b") as held:
        os.dup2(held.fileno(), 2)
        missing = False
        try:
            yield
        except NetsimUnavailable:
            missing = True  # (the `ns` stub's own advice: ours says it on one line)
            raise
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            kept = [
                line
                for line in held.read().decode(errors="replace").splitlines(keepends=True)
                if not line.startswith(_CLING_NOISE)
            ]
            if kept and not missing:
                sys.stderr.write("".join(kept))
                sys.stderr.flush()


def data_schedule(scenario: NetScenario, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every data packet: mission send time, source kind ("uav"/"user") and 1-based id, in
    time order. Each source sends every `packet_interval_s` from a phase drawn uniformly in
    [0, interval) (numpy, seeded with `seed`), from the first sample to the last."""
    interval = scenario.packet_interval_s
    start, end = float(scenario.times[0]), float(scenario.times[-1])
    sources = [("uav", k + 1) for k in range(scenario.fleet_size)]
    sources += [("user", k + 1) for k in range(len(scenario.ground_users))]
    phases = np.random.default_rng(seed).uniform(0.0, interval, len(sources))
    times, kinds, ids = [], [], []
    for (kind, number), phase in zip(sources, phases, strict=True):
        sent = np.arange(start + phase, end, interval)
        times.append(sent)
        kinds += [kind] * len(sent)
        ids.append(np.full(len(sent), number))
    times_all = np.concatenate(times) if times else np.zeros(0)
    order = np.argsort(times_all, kind="stable")
    return (
        times_all[order],
        np.array(kinds, dtype="<U4")[order],
        (np.concatenate(ids) if ids else np.zeros(0, int))[order],
    )


def log_distance_exponent(radio_range: float) -> float:
    """The path-loss exponent that puts `RX_THRESHOLD_DBM` at `radio_range` (m)."""
    return (TX_POWER_DBM - RX_THRESHOLD_DBM - REFERENCE_LOSS_DB) / (10 * math.log10(radio_range))


def _footprint_vectors(ns, buildings: dict):
    """`planner.sight.sight_json`'s obstacles as the C++ model's vectors: ring points (x, y
    flat), points per ring, walls (x0, y0, x1, y1 flat)."""
    std = ns.cppyy.gbl.std
    rings = [np.asarray(ring, dtype=float).reshape(-1, 2) for ring in buildings["polygons"]]
    xy = std.vector["double"]([float(v) for ring in rings for v in ring.reshape(-1)])
    sizes = std.vector["uint32_t"]([len(ring) for ring in rings])
    walls = std.vector["double"](
        [float(v) for v in np.asarray(buildings["walls"], dtype=float).reshape(-1)]
    )
    return xy, sizes, walls


def _add_footprint_loss(ns, channel, scenario: NetScenario) -> dict:
    """Links through the scenario's buildings cut beyond its NLOS range, in front of the
    channel's propagation loss (`fleetline_netsim::FootprintLoss`)."""
    xy, sizes, walls = _footprint_vectors(ns, scenario.buildings)
    ns.cppyy.gbl.fleetline_netsim.AddFootprintLoss(
        channel, xy, sizes, walls, float(scenario.nlos_range_m)
    )
    return {
        "footprints": len(sizes),
        "walls": len(walls) // 4,
        "nlos_range_m": float(scenario.nlos_range_m),
    }


def footprint_blocked(buildings: dict, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Whether the C++ model (`fleetline_netsim::FootprintLoss`) finds each chord
    starts[i] -> ends[i] blocked by `buildings` (for tests against `planner.sight`)."""
    ns = load_ns3()
    xy, sizes, walls = _footprint_vectors(ns, buildings)
    blocked = ns.cppyy.gbl.fleetline_netsim.FootprintBlocked
    return np.array(
        [
            blocked(xy, sizes, walls, *map(float, a), *map(float, b))
            for a, b in zip(starts, ends, strict=True)
        ],
        dtype=bool,
    )


def run_network(scenario: NetScenario, options: NetOptions = NetOptions()) -> NetResult:
    """Simulate `scenario` in ns-3 (module docstring); `NetsimUnavailable` without ns-3."""
    began = time.perf_counter()
    ns = load_ns3()
    import_s = time.perf_counter() - began
    began = time.perf_counter()
    uavs, stations = scenario.fleet_size, len(scenario.base_stations)
    users = len(scenario.ground_users)
    count = uavs + stations + users
    offset = WARMUP_S - float(scenario.times[0])  # sim s = mission s + offset

    ns.RngSeedManager.SetSeed(1)
    ns.RngSeedManager.SetRun(int(options.seed))
    ns.RngSeedManager.ResetNextStreamIndex()
    ns.Ipv4AddressGenerator.Reset()
    ns.Config.SetDefault("ns3::ArpCache::DeadTimeout", ns.TimeValue(ns.Seconds(ARP_DEAD_S)))

    nodes = ns.NodeContainer()
    nodes.Create(count)
    moving, fixed = ns.NodeContainer(), ns.NodeContainer()
    for k in range(count):
        (moving if k < uavs else fixed).Add(nodes.Get(k))

    wifi = ns.WifiHelper()
    wifi.SetStandard(ns.WIFI_STANDARD_80211b)
    wifi.SetRemoteStationManager(
        "ns3::ConstantRateWifiManager",
        "DataMode",
        ns.StringValue("DsssRate11Mbps"),
        "ControlMode",
        ns.StringValue("DsssRate1Mbps"),
    )
    channel = ns.YansWifiChannelHelper()
    channel.SetPropagationDelay("ns3::ConstantSpeedPropagationDelayModel")
    phy = ns.YansWifiPhyHelper()
    extra: dict[str, Any] = {"import_s": dict(IMPORT_TIMES), "arp_dead_s": ARP_DEAD_S}
    if options.propagation == "range":
        channel.AddPropagationLoss(
            "ns3::RangePropagationLossModel", "MaxRange", ns.DoubleValue(scenario.radio_range)
        )
    else:
        exponent = log_distance_exponent(scenario.radio_range)
        channel.AddPropagationLoss(
            "ns3::LogDistancePropagationLossModel",
            "Exponent",
            ns.DoubleValue(exponent),
            "ReferenceDistance",
            ns.DoubleValue(1.0),
            "ReferenceLoss",
            ns.DoubleValue(REFERENCE_LOSS_DB),
        )
        phy.Set("RxSensitivity", ns.DoubleValue(RX_THRESHOLD_DBM))
        extra["log_distance"] = {
            "exponent": exponent,
            "reference_loss_db": REFERENCE_LOSS_DB,
            "rx_threshold_dbm": RX_THRESHOLD_DBM,
        }
    phy.Set("TxPowerStart", ns.DoubleValue(TX_POWER_DBM))
    phy.Set("TxPowerEnd", ns.DoubleValue(TX_POWER_DBM))
    yans = channel.Create()
    if scenario.buildings is not None:
        extra["buildings"] = _add_footprint_loss(ns, yans, scenario)
    phy.SetChannel(yans)
    mac = ns.WifiMacHelper()
    mac.SetType("ns3::AdhocWifiMac")
    devices = wifi.Install(phy, mac, nodes)

    mobility = ns.MobilityHelper()
    mobility.SetMobilityModel("ns3::WaypointMobilityModel", "LazyNotify", ns.BooleanValue(True))
    mobility.Install(moving)
    allocator = ns.ListPositionAllocator()
    for x, y in np.concatenate([scenario.base_stations, scenario.ground_users]):
        allocator.Add(ns.Vector(float(x), float(y), 0.0))
    fixed_helper = ns.MobilityHelper()
    fixed_helper.SetPositionAllocator(allocator)
    fixed_helper.SetMobilityModel("ns3::ConstantPositionMobilityModel")
    fixed_helper.Install(fixed)

    stack = ns.InternetStackHelper()
    if options.routing == "aodv":
        routing = ns.AodvHelper()
        routing.Set("HelloInterval", ns.TimeValue(ns.Seconds(options.hello_s)))
        stack.SetRoutingHelper(routing)
    else:
        routing = ns.OlsrHelper()
        routing.Set("HelloInterval", ns.TimeValue(ns.Seconds(options.hello_s)))
        stack.SetRoutingHelper(routing)
    stack.Install(nodes)
    addresses = ns.Ipv4AddressHelper()
    addresses.SetBase(ns.Ipv4Address("10.1.0.0"), ns.Ipv4Mask("255.255.0.0"))
    addresses.Assign(devices)

    stream = 0
    stream += wifi.AssignStreams(devices, stream)
    stream += routing.AssignStreams(nodes, stream)
    stream += stack.AssignStreams(nodes, stream)

    net = ns.cppyy.gbl.fleetline_netsim.Net(
        uavs, stations, users, int(scenario.packet_bytes), PORT, float(options.wired_delay_s)
    )
    for k in range(count):
        net.AddNode(nodes.Get(k))
    net.Install()

    sim_times = np.ascontiguousarray(scenario.times + offset, dtype=np.float64)
    table = np.ascontiguousarray(station_table(scenario), dtype=np.int32)
    net.SetStations(table, table.shape[0], table.shape[1], float(sim_times[0]), SAMPLE_HZ)
    positions = scenario.uav_positions.copy()
    if options.geometry == "2d":
        positions[..., 2] = 0.0
    waypoint_times = np.ascontiguousarray(np.concatenate([[0.0], sim_times]))
    for k in range(uavs):
        # from sim time 0 (the warm-up) at the first sample's position
        xyz = np.ascontiguousarray(np.vstack([positions[:1, k], positions[:, k]]))
        net.SetWaypoints(k, waypoint_times, xyz, len(waypoint_times))

    sent, kinds, ids = data_schedule(scenario, int(options.seed))
    node_of = np.where(kinds == "uav", ids - 1, uavs + stations + ids - 1).astype(np.int32)
    if len(sent):
        net.ScheduleData(np.ascontiguousarray(sent + offset, dtype=np.float64), node_of, len(sent))
    request_times = np.array([r.t for r in scenario.requests], dtype=np.float64) + offset
    leaders = np.array([r.leader - 1 for r in scenario.requests], dtype=np.int32)
    # a request before the first sample is sent at the first sample
    request_times = np.ascontiguousarray(np.maximum(request_times, WARMUP_S))
    if len(leaders):  # cppyy passes no buffer for an empty array
        net.ScheduleRequests(request_times, leaders, len(leaders))
    end = float(scenario.times[-1]) + offset + DRAIN_S
    ns.Simulator.Stop(ns.Seconds(end))
    build_s = time.perf_counter() - began

    began = time.perf_counter()
    ns.Simulator.Run()
    run_s = time.perf_counter() - began

    def fetch(name: str) -> np.ndarray:
        out = np.empty(int(net.Size(name)), dtype=np.float64)
        if out.size:
            net.Copy(name, out)
        return out

    requests, size = len(scenario.requests), (len(scenario.requests), uavs)
    results = {
        name: fetch(name)
        for name in (
            "data_sent",
            "data_received",
            "data_hops",
            "data_station",
            "paper_received",
            "paper_hops",
            "paper_relays",
            "gcs_received",
            "gcs_hops",
            "uplink_received",
            "uplink_hops",
            "uplink_station",
        )
    }
    ns.Simulator.Destroy()  # (every node, socket and event: the next run starts afresh)
    return NetResult(
        scenario=scenario,
        options=options,
        source_kind=kinds,
        source_id=ids.astype(int),
        sent_s=results["data_sent"] - offset,
        received_s=results["data_received"] - offset,
        hops=results["data_hops"].astype(int),
        station=results["data_station"].astype(int),
        paper_received_s=results["paper_received"].reshape(size) - offset,
        paper_hops=results["paper_hops"].reshape(size).astype(int),
        paper_relays=results["paper_relays"].reshape(size).astype(int),
        gcs_received_s=results["gcs_received"].reshape(size) - offset,
        gcs_hops=results["gcs_hops"].reshape(size).astype(int),
        uplink_received_s=results["uplink_received"].reshape(requests) - offset,
        uplink_hops=results["uplink_hops"].astype(int),
        uplink_station=results["uplink_station"].astype(int),
        import_s=import_s,
        build_s=build_s,
        run_s=run_s,
        extra=extra,
    )
