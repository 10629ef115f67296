"""The C++ side of `gcs.netsim.ns3`, compiled once per process by cppyy (ns-3's bindings).

`fleetline_netsim::Net` owns one UDP socket per node (port `port`) and, per packet, writes a
24-byte header (kind, packet id, request index, step, relays, hops) at the start of a
`payload`-byte UDP payload. It sends the data packets at the times it is given, each to the
base station its source sends to at that instant (`SetStations`: a table per 10 Hz sample,
made by `gcs.netsim.scenario.station_table`), and relays the speed requests:

* the paper's chain (kind PAPER): the leader sends one unicast packet to each of its
  neighbours in the line (k+1 and k-1), and each UAV, on receipt, forwards it once to the
  next one away from the leader, until the ends of the line;
* the ground station's relay (UPLINK then DOWNLINK): the leader sends to its base station;
  on receipt (the ground station is wired to every base station), `wired_delay` later, the
  base station of each other UAV sends it to that UAV.

A packet's hops are 1 + the times a node other than its source forwarded it (the
Ipv4L3Protocol `UnicastForward` trace; AODV's packets waiting at their source for a route go
through it once there, which an IP TTL count would take for a hop); a chain's hops add up the
radio hops of its packets. Results are arrays of doubles (NaN, -1: never), copied out by
`Copy`.
"""

SOURCE = r"""
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <string>
#include <unordered_map>
#include <vector>

namespace fleetline_netsim
{
using namespace ns3;

struct Header
{
    uint32_t kind;
    uint32_t id;
    uint32_t request;
    int32_t step;   // paper chain: +1 towards N, -1 towards 1
    uint32_t relays; // paper chain: packets of the chain so far, this one included
    uint32_t hops;   // paper chain: radio hops of the chain before this packet
};

enum Kind : uint32_t
{
    DATA = 0,
    PAPER = 1,
    UPLINK = 2,
    DOWNLINK = 3
};

static const uint32_t REQUEST_IDS = 1u << 30; // ids of the relay packets start here

class Net
{
  public:
    Net(uint32_t uavs, uint32_t stations, uint32_t users, uint32_t payload, uint16_t port,
        double wiredDelay)
        : m_uavs(uavs),
          m_stations(stations),
          m_users(users),
          m_payload(payload),
          m_port(port),
          m_wiredDelay(wiredDelay),
          m_nextId(REQUEST_IDS)
    {
    }

    void AddNode(Ptr<Node> node)
    {
        m_nodes.push_back(node);
    }

    // UAV `index`'s trajectory: `count` samples (sim s, x, y, z row-major)
    void SetWaypoints(uint32_t index, const double* t, const double* xyz, uint32_t count)
    {
        Ptr<WaypointMobilityModel> model = m_nodes[index]->GetObject<WaypointMobilityModel>();
        for (uint32_t k = 0; k < count; ++k)
        {
            model->AddWaypoint(
                Waypoint(Seconds(t[k]), Vector(xyz[3 * k], xyz[3 * k + 1], xyz[3 * k + 2])));
        }
    }

    void Install()
    {
        for (uint32_t i = 0; i < m_nodes.size(); ++i)
        {
            Ptr<Node> node = m_nodes[i];
            m_index[node->GetId()] = i;
            m_address.push_back(node->GetObject<Ipv4>()->GetAddress(1, 0).GetLocal());
            Ptr<Socket> socket = Socket::CreateSocket(node, UdpSocketFactory::GetTypeId());
            socket->Bind(InetSocketAddress(Ipv4Address::GetAny(), m_port));
            socket->SetRecvCallback(MakeCallback(&Net::Receive, this));
            m_sockets.push_back(socket);
            node->GetObject<Ipv4L3Protocol>()->TraceConnect("UnicastForward",
                                                            std::to_string(i),
                                                            MakeCallback(&Net::Forwarded, this));
        }
    }

    // row k of `table` (rows x columns, UAVs then ground users): the base station (0-based)
    // each sends to from sim time start + k / rate
    void SetStations(const int32_t* table, uint32_t rows, uint32_t columns, double start,
                     double rate)
    {
        m_table.assign(table, table + rows * columns);
        m_tableRows = rows;
        m_tableColumns = columns;
        m_tableStart = start;
        m_tableRate = rate;
    }

    // data packet k: sent at t[k] (sim s) by node source[k]
    void ScheduleData(const double* t, const int32_t* source, uint32_t count)
    {
        const double nan = std::numeric_limits<double>::quiet_NaN();
        m_dataSource.assign(source, source + count);
        m_out["data_sent"].assign(count, nan);
        m_out["data_received"].assign(count, nan);
        m_out["data_hops"].assign(count, -1.0);
        m_out["data_station"].assign(count, -1.0);
        for (uint32_t k = 0; k < count; ++k)
        {
            Simulator::Schedule(Seconds(t[k]), &Net::SendData, this, k);
        }
    }

    // request r: sent at t[r] (sim s) by UAV leader[r] (0-based)
    void ScheduleRequests(const double* t, const int32_t* leader, uint32_t count)
    {
        const double nan = std::numeric_limits<double>::quiet_NaN();
        m_leader.assign(leader, leader + count);
        for (const char* name : {"paper_received", "gcs_received"})
        {
            m_out[name].assign(count * m_uavs, nan);
        }
        for (const char* name : {"paper_hops", "paper_relays", "gcs_hops"})
        {
            m_out[name].assign(count * m_uavs, -1.0);
        }
        m_out["uplink_received"].assign(count, nan);
        m_out["uplink_station"].assign(count, -1.0);
        m_out["uplink_hops"].assign(count, -1.0);
        for (uint32_t r = 0; r < count; ++r)
        {
            Simulator::Schedule(Seconds(t[r]), &Net::SendRequest, this, r);
        }
    }

    uint32_t Size(const std::string& name)
    {
        return m_out[name].size();
    }

    void Copy(const std::string& name, double* out)
    {
        const std::vector<double>& values = m_out[name];
        std::memcpy(out, values.data(), values.size() * sizeof(double));
    }

  private:
    uint32_t NewId()
    {
        return m_nextId++;
    }

    // the base station node UAV or ground user `index` sends to now (`SetStations`)
    uint32_t StationOf(uint32_t index)
    {
        uint32_t column = index < m_uavs ? index : index - m_stations;
        double sample = std::floor((Simulator::Now().GetSeconds() - m_tableStart) * m_tableRate + 1e-6);
        uint32_t row = sample <= 0 ? 0 : std::min((uint32_t)sample, m_tableRows - 1);
        return m_uavs + m_table[row * m_tableColumns + column];
    }

    void Send(uint32_t from, uint32_t to, uint32_t kind, uint32_t id, uint32_t request,
              int32_t step = 0, uint32_t relays = 0, uint32_t hops = 0)
    {
        std::vector<uint8_t> buffer(m_payload, 0);
        Header header{kind, id, request, step, relays, hops};
        std::memcpy(buffer.data(), &header, sizeof header);
        Ptr<Packet> packet = Create<Packet>(buffer.data(), m_payload);
        m_sockets[from]->SendTo(packet, 0, InetSocketAddress(m_address[to], m_port));
    }

    void SendData(uint32_t k)
    {
        uint32_t source = m_dataSource[k];
        uint32_t station = StationOf(source);
        m_out["data_sent"][k] = Simulator::Now().GetSeconds();
        m_out["data_station"][k] = station - m_uavs;
        Send(source, station, DATA, k, 0);
    }

    void SendRequest(uint32_t r)
    {
        uint32_t leader = m_leader[r];
        double now = Simulator::Now().GetSeconds();
        uint32_t cell = r * m_uavs + leader;
        m_out["paper_received"][cell] = now;
        m_out["gcs_received"][cell] = now;
        m_out["paper_hops"][cell] = 0;
        m_out["paper_relays"][cell] = 0;
        m_out["gcs_hops"][cell] = 0;
        if (leader + 1 < m_uavs)
        {
            Send(leader, leader + 1, PAPER, NewId(), r, 1, 1, 0);
        }
        if (leader > 0)
        {
            Send(leader, leader - 1, PAPER, NewId(), r, -1, 1, 0);
        }
        Send(leader, StationOf(leader), UPLINK, NewId(), r);
    }

    void Downlink(uint32_t r)
    {
        for (uint32_t uav = 0; uav < m_uavs; ++uav)
        {
            if (uav != (uint32_t)m_leader[r])
            {
                Send(StationOf(uav), uav, DOWNLINK, NewId(), r);
            }
        }
    }

    int32_t Hops(uint32_t id)
    {
        auto found = m_forwards.find(id);
        return 1 + (found == m_forwards.end() ? 0 : (int32_t)found->second);
    }

    void Receive(Ptr<Socket> socket)
    {
        uint32_t at = m_index[socket->GetNode()->GetId()];
        Ptr<Packet> packet;
        while ((packet = socket->Recv()))
        {
            if (packet->GetSize() < sizeof(Header))
            {
                continue;
            }
            Header header;
            packet->CopyData(reinterpret_cast<uint8_t*>(&header), sizeof header);
            double now = Simulator::Now().GetSeconds();
            bool uav = at < m_uavs;
            bool station = at >= m_uavs && at < m_uavs + m_stations;
            if (header.kind == DATA && station && header.id < m_dataSource.size())
            {
                std::vector<double>& received = m_out["data_received"];
                if (std::isnan(received[header.id]))
                {
                    received[header.id] = now;
                    m_out["data_hops"][header.id] = Hops(header.id);
                }
            }
            else if (header.kind == PAPER && uav && header.request < m_leader.size())
            {
                uint32_t cell = header.request * m_uavs + at;
                std::vector<double>& received = m_out["paper_received"];
                if (std::isnan(received[cell]))
                {
                    uint32_t hops = header.hops + Hops(header.id);
                    received[cell] = now;
                    m_out["paper_hops"][cell] = hops;
                    m_out["paper_relays"][cell] = header.relays;
                    int32_t next = (int32_t)at + header.step;
                    if (next >= 0 && next < (int32_t)m_uavs)
                    {
                        Send(at, next, PAPER, NewId(), header.request, header.step,
                             header.relays + 1, hops);
                    }
                }
            }
            else if (header.kind == UPLINK && station && header.request < m_leader.size())
            {
                std::vector<double>& received = m_out["uplink_received"];
                if (std::isnan(received[header.request]))
                {
                    received[header.request] = now;
                    m_out["uplink_station"][header.request] = at - m_uavs;
                    m_out["uplink_hops"][header.request] = Hops(header.id);
                    Simulator::Schedule(Seconds(m_wiredDelay),
                                        &Net::Downlink,
                                        this,
                                        header.request);
                }
            }
            else if (header.kind == DOWNLINK && uav && header.request < m_leader.size())
            {
                uint32_t cell = header.request * m_uavs + at;
                std::vector<double>& received = m_out["gcs_received"];
                if (std::isnan(received[cell]))
                {
                    received[cell] = now;
                    m_out["gcs_hops"][cell] = Hops(header.id);
                }
            }
        }
    }

    void Forwarded(std::string context, const Ipv4Header& ip, Ptr<const Packet> packet,
                   uint32_t interface)
    {
        if (ip.GetProtocol() != 17 || packet->GetSize() < 8 + sizeof(Header))
        {
            return;
        }
        uint32_t at = std::stoul(context);
        if (ip.GetSource() == m_address[at])
        {
            return; // its source (AODV's deferred packets)
        }
        uint8_t buffer[8 + sizeof(Header)];
        packet->CopyData(buffer, sizeof buffer);
        if (((buffer[2] << 8) | buffer[3]) != m_port)
        {
            return;
        }
        Header header;
        std::memcpy(&header, buffer + 8, sizeof header);
        m_forwards[header.id] += 1;
    }

    uint32_t m_uavs, m_stations, m_users, m_payload;
    uint16_t m_port;
    double m_wiredDelay;
    uint32_t m_nextId;
    std::vector<Ptr<Node>> m_nodes;
    std::vector<Ipv4Address> m_address;
    std::vector<Ptr<Socket>> m_sockets;
    std::unordered_map<uint32_t, uint32_t> m_index;
    std::unordered_map<uint32_t, uint32_t> m_forwards;
    std::vector<int32_t> m_dataSource;
    std::vector<int32_t> m_leader;
    std::vector<int32_t> m_table;
    uint32_t m_tableRows = 0, m_tableColumns = 0;
    double m_tableStart = 0, m_tableRate = 1;
    std::map<std::string, std::vector<double>> m_out;
};

// Links through buildings, exactly as the medium's `medium.pathloss.ThroughBuildings`: a
// chord whose horizontal projection meets a footprint or a wall (touching counts) lives only
// up to `nlosRange` metres (0: never); the channel's own model (range or log-distance) then
// applies. Footprints are rings (x, y flat, `sizes` points each); walls are x0 y0 x1 y1.
// (ns-3's buildings module takes boxes, not footprints: hence a model of our own.)
class Footprints
{
  public:
    Footprints(const std::vector<double>& xy, const std::vector<uint32_t>& sizes,
               const std::vector<double>& walls)
    {
        size_t at = 0;
        for (uint32_t size : sizes)
        {
            std::vector<double> ring(xy.begin() + 2 * at, xy.begin() + 2 * (at + size));
            double box[4] = {1e300, 1e300, -1e300, -1e300};
            for (uint32_t k = 0; k < size; ++k)
            {
                box[0] = std::min(box[0], ring[2 * k]);
                box[1] = std::min(box[1], ring[2 * k + 1]);
                box[2] = std::max(box[2], ring[2 * k]);
                box[3] = std::max(box[3], ring[2 * k + 1]);
            }
            m_rings.push_back(ring);
            m_boxes.push_back({box[0], box[1], box[2], box[3]});
            at += size;
        }
        m_walls = walls;
    }

    bool Blocked(double ax, double ay, double bx, double by) const
    {
        for (size_t w = 0; w + 3 < m_walls.size(); w += 4)
        {
            if (Cross(ax, ay, bx, by, m_walls[w], m_walls[w + 1], m_walls[w + 2], m_walls[w + 3]))
                return true;
        }
        for (size_t r = 0; r < m_rings.size(); ++r)
        {
            const auto& box = m_boxes[r];
            if (std::max(ax, bx) < box[0] || std::min(ax, bx) > box[2] ||
                std::max(ay, by) < box[1] || std::min(ay, by) > box[3])
                continue;
            const auto& ring = m_rings[r];
            size_t n = ring.size() / 2;
            if (Inside(ring, ax, ay) || Inside(ring, bx, by))
                return true;
            for (size_t k = 0; k < n; ++k)
            {
                size_t j = (k + 1) % n;
                if (Cross(ax, ay, bx, by, ring[2 * k], ring[2 * k + 1], ring[2 * j],
                          ring[2 * j + 1]))
                    return true;
            }
        }
        return false;
    }

  private:
    static double Orient(double ax, double ay, double bx, double by, double cx, double cy)
    {
        return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    }

    static bool Within(double a, double b, double c)
    {
        return std::min(a, b) <= c && c <= std::max(a, b);
    }

    // segments ab and cd meet (touching included)
    static bool Cross(double ax, double ay, double bx, double by, double cx, double cy,
                      double dx, double dy)
    {
        double d1 = Orient(cx, cy, dx, dy, ax, ay), d2 = Orient(cx, cy, dx, dy, bx, by);
        double d3 = Orient(ax, ay, bx, by, cx, cy), d4 = Orient(ax, ay, bx, by, dx, dy);
        if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0)))
            return true;
        if (d1 == 0 && Within(cx, dx, ax) && Within(cy, dy, ay)) return true;
        if (d2 == 0 && Within(cx, dx, bx) && Within(cy, dy, by)) return true;
        if (d3 == 0 && Within(ax, bx, cx) && Within(ay, by, cy)) return true;
        if (d4 == 0 && Within(ax, bx, dx) && Within(ay, by, dy)) return true;
        return false;
    }

    // strictly inside the ring (its boundary is caught by Cross)
    static bool Inside(const std::vector<double>& ring, double x, double y)
    {
        bool inside = false;
        size_t n = ring.size() / 2;
        for (size_t k = 0, j = n - 1; k < n; j = k++)
        {
            double xk = ring[2 * k], yk = ring[2 * k + 1], xj = ring[2 * j], yj = ring[2 * j + 1];
            if ((yk > y) != (yj > y) && x < (xj - xk) * (y - yk) / (yj - yk) + xk)
                inside = !inside;
        }
        return inside;
    }

    std::vector<std::vector<double>> m_rings;
    std::vector<std::array<double, 4>> m_boxes;
    std::vector<double> m_walls;
};

class FootprintLoss : public PropagationLossModel
{
  public:
    FootprintLoss(const std::vector<double>& xy, const std::vector<uint32_t>& sizes,
                  const std::vector<double>& walls, double nlosRange)
        : m_footprints(xy, sizes, walls),
          m_nlosRange(nlosRange)
    {
    }

  private:
    double DoCalcRxPower(double txPowerDbm, Ptr<MobilityModel> a,
                         Ptr<MobilityModel> b) const override
    {
        Vector pa = a->GetPosition(), pb = b->GetPosition();
        if (std::hypot(pb.x - pa.x, pb.y - pa.y) > m_nlosRange &&
            m_footprints.Blocked(pa.x, pa.y, pb.x, pb.y))
            return -1000.0;
        return txPowerDbm;
    }

    int64_t DoAssignStreams(int64_t) override
    {
        return 0;
    }

    Footprints m_footprints;
    double m_nlosRange;
};

// Put a FootprintLoss in front of `channel`'s propagation loss model.
inline void AddFootprintLoss(Ptr<YansWifiChannel> channel, const std::vector<double>& xy,
                             const std::vector<uint32_t>& sizes, const std::vector<double>& walls,
                             double nlosRange)
{
    PointerValue current;
    channel->GetAttribute("PropagationLossModel", current);
    Ptr<FootprintLoss> loss = Create<FootprintLoss>(xy, sizes, walls, nlosRange);
    loss->SetNext(current.Get<PropagationLossModel>());
    channel->SetPropagationLossModel(loss);
}

// What FootprintLoss decides for one chord (tests: the same as `planner.sight.Sight`).
inline bool FootprintBlocked(const std::vector<double>& xy, const std::vector<uint32_t>& sizes,
                             const std::vector<double>& walls, double ax, double ay, double bx,
                             double by)
{
    return Footprints(xy, sizes, walls).Blocked(ax, ay, bx, by);
}

} // namespace fleetline_netsim
"""
