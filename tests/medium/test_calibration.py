"""The calibrated radio model (pure, no ns-3): the table's loading and validation, seeded draws
that follow its quantiles and loss ratios, the load level nearest the offered load, the
extrapolation beyond the largest measured hop count; the simple model left as it was; the
mission's `radio.model` and `radio.calibration`, the medium's `--model` and `--calibration`,
the fast mode flying with the calibrated model; `gcs eval calibrate`'s scenarios, reduction
and refusals before ns-3 is needed (tests/medium/test_calibration_ns3.py runs it in ns-3).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from gcs.errors import InputError
from gcs.mission import load_mission
from gcs.netsim.calibrate import (
    QUANTILES,
    QUICK_PLAN,
    CalibrationPlan,
    calibration_table,
    hop_row,
    line_scenario,
    table_json,
)
from gcs.netsim.ns3 import NetOptions
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast, radio_config
from gcs.sim.medium_process import medium_setup, model_args
from medium import cli as medium_cli
from medium.calibration import (
    DEFAULT_CALIBRATION,
    CalibrationTable,
    calibration_from_json,
    load_calibration,
)
from medium.medium import MediumModel, offered_data_bps
from medium.radio import Channel, RadioConfig, topology
from medium.radio_stats import KINDS
from tests.conftest import MISSIONS
from tests.mission_texts import MINIMAL

PROBABILITIES = [0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 0.99, 1.0]


def row(hops: int, loss: float, delays_ms: list[float]) -> dict:
    return {
        "hops": hops,
        "sent": 1000,
        "lost": round(1000 * loss),
        "loss_ratio": loss,
        "delay_s": [d / 1000.0 for d in delays_ms],
    }


#: Two load levels, 1..3 hops, quantiles spread out (the shipped table's lowest level is
#: nearly a constant per hop count: useless to check a sampler against).
SYNTHETIC = {
    "format": "fleetline-radio-calibration",
    "version": 1,
    "quantiles": PROBABILITIES,
    "levels": [
        {
            "offered_load_bps": 8000.0,
            "hops": [
                row(1, 0.0, [0.4, 0.5, 0.6, 0.8, 1.0, 1.5, 3.0, 8.0]),
                row(2, 0.1, [1.0, 1.1, 1.4, 1.7, 2.0, 3.0, 6.0, 20.0]),
                row(3, 0.3, [1.5, 1.8, 2.2, 2.6, 3.2, 5.0, 9.0, 40.0]),
            ],
        },
        {
            "offered_load_bps": 32000.0,
            "hops": [
                row(1, 0.0, [0.4, 0.6, 0.9, 1.2, 1.6, 2.5, 4.0, 9.0]),
                row(2, 0.2, [1.0, 1.4, 2.0, 2.6, 3.4, 5.0, 9.0, 30.0]),
                row(3, 0.4, [1.6, 2.2, 3.0, 4.0, 5.0, 8.0, 15.0, 60.0]),
            ],
        },
    ],
}


@pytest.fixture(scope="module")
def synthetic() -> CalibrationTable:
    return calibration_from_json(SYNTHETIC, "synthetic.json")


def calibrated(table: CalibrationTable, seed: int = 4, load: float | None = 8000.0) -> Channel:
    return Channel(
        RadioConfig(100.0, seed=seed, model="calibrated", calibration=table, offered_load_bps=load)
    )


# --------------------------------------------------------------------------- the table
def test_the_shipped_table_loads_with_four_loads_and_ten_hop_counts():
    table = load_calibration()
    assert Path(table.source) == DEFAULT_CALIBRATION
    assert table.probabilities == QUANTILES
    loads = table.offered_loads_bps
    assert (np.diff(loads) > 0).all() and len(loads) >= 3
    assert table.levels[0].rate_bps_per_node == 800.0  # the paper's load
    for level in table.levels:
        assert level.max_hops == 10
        assert (level.sent >= 300).all()
        medians = level.quantiles_s[:, QUANTILES.index(0.5)]
        assert 0.0002 < medians[0] < 0.002  # hundreds of microseconds for one hop
        assert medians[-1] > medians[0]
    assert "gcs eval calibrate" in table.made_by["command"]
    assert table.ns3["version"].startswith("3.44")


def mutated(path: list, value) -> dict:
    data = copy.deepcopy(SYNTHETIC)
    target = data
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return data


@pytest.mark.parametrize(
    ("path", "value", "named"),
    [
        (["format"], "other", "format"),
        (["version"], 7, "version"),
        (["levels"], KeyError, "levels"),
        (["levels"], [], "levels"),
        (["quantiles"], [0.1, 0.5, 1.0], "quantiles"),
        (["quantiles", 2], "x", "quantiles[2]"),
        (["levels", 0, "offered_load_bps"], 0, "levels[0].offered_load_bps"),
        (["levels", 1, "offered_load_bps"], 100.0, "levels"),  # not increasing
        (["levels", 0, "hops", 1, "hops"], 3, "levels[0].hops[1].hops"),
        (["levels", 0, "hops", 1, "sent"], 0, "levels[0].hops[1].sent"),
        (["levels", 1, "hops", 2, "loss_ratio"], 1.5, "levels[1].hops[2].loss_ratio"),
        (["levels", 0, "hops", 0, "delay_s"], [0.002, 0.001] * 4, "levels[0].hops[0].delay_s"),
        (["levels", 0, "hops", 0, "delay_s"], [0.001] * 3, "levels[0].hops[0].delay_s"),
        (["levels", 0, "hops", 0, "delay_s"], None, "levels[0].hops[0].delay_s"),
        (["levels", 0, "hops", 2, "delay_s", 4], -1.0, "levels[0].hops[2].delay_s[4]"),
        (["levels", 0, "hops", 2, "loss_ratio"], KeyError, "levels[0].hops[2].loss_ratio"),
    ],
)
def test_a_bad_table_is_refused_naming_the_key(tmp_path, path, value, named):
    file = tmp_path / "table.json"
    file.write_text(json.dumps(mutated(path, value)))
    with pytest.raises(ValueError) as caught:
        load_calibration(file)
    message = str(caught.value)
    assert message.startswith(f"{file}: {named}: expected"), message
    assert "\n" not in message


def test_a_file_that_is_not_json_or_missing_is_refused(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match=r"bad\.json: expected JSON"):
        load_calibration(bad)
    with pytest.raises(ValueError, match=r"missing\.json: expected a readable calibration"):
        load_calibration(tmp_path / "missing.json")


def test_a_hop_count_with_nothing_delivered_loses_every_packet():
    data = mutated(["levels", 0, "hops", 2], {"hops": 3, "sent": 10, "loss_ratio": 1.0,
                                              "delay_s": None})  # fmt: skip
    level = calibration_from_json(data).levels[0]
    assert np.isnan(level.delays(np.full(50, 3), np.zeros(50), np.full(50, 0.5))).all()
    assert level.delay(3, 0.0, 0.5) is None
    assert level.delay(5, 0.0, 0.5) is None  # beyond H too


# --------------------------------------------------------------------------- draws
def test_draws_are_deterministic_per_seed(synthetic):
    hops = np.tile([1, 2, 3, 7], 500)
    first, again, other = (calibrated(synthetic, seed).transit_many(hops) for seed in (4, 4, 5))
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other, equal_nan=True)
    one, two = calibrated(synthetic, 4), calibrated(synthetic, 4)
    assert [one.transit(h) for h in hops.tolist()] == [two.transit(h) for h in hops.tolist()]


def test_one_packet_at_a_time_draws_what_many_at_once_draw(synthetic):
    hops = np.random.default_rng(2).integers(1, 8, 3000)
    many = calibrated(synthetic, 9).transit_many(hops)
    channel = calibrated(synthetic, 9)
    singles = np.array([np.nan if (d := channel.transit(h)) is None else d for h in hops.tolist()])
    np.testing.assert_allclose(singles, many, rtol=1e-12, equal_nan=True)


@pytest.mark.parametrize("load", [8000.0, 32000.0])
@pytest.mark.parametrize("hops", [1, 2, 3])
def test_sampled_delays_follow_the_table_quantiles_and_loss(synthetic, load, hops):
    """At each stored quantile q_p the share of delivered delays at or below it is p (within
    4 standard errors of 40 000 draws), the delays never leave [p0, p100], and the share lost
    is the loss ratio."""
    size = 40_000
    delays = calibrated(synthetic, 11, load).transit_many(np.full(size, hops))
    level = synthetic.level(load)
    lost = np.isnan(delays)
    ratio = level.loss_ratio[hops - 1]
    assert lost.mean() == pytest.approx(ratio, abs=4 * np.sqrt(ratio * (1 - ratio) / size) + 1e-9)
    delivered = delays[~lost]
    stored = level.quantiles_s[hops - 1]
    assert delivered.min() >= stored[0] and delivered.max() <= stored[-1]
    error = 4 * np.sqrt(0.25 / len(delivered))
    for probability, quantile in zip(PROBABILITIES[1:-1], stored[1:-1], strict=True):
        assert (delivered <= quantile).mean() == pytest.approx(probability, abs=error)


def test_the_level_is_the_nearest_load_on_a_log_scale(synthetic):
    loads = [synthetic.level(load).offered_load_bps for load in
             (None, 0.0, 10.0, 8000.0, 15000.0, 16000.0, 17000.0, 1e9)]  # fmt: skip
    # 16 000 is as far from 8 000 as from 32 000 on a log scale: the higher load
    assert loads == [8000.0, 8000.0, 8000.0, 8000.0, 8000.0, 32000.0, 32000.0, 32000.0]
    channel = Channel(RadioConfig(100.0, model="calibrated", calibration=synthetic), 0, 30000.0)
    assert channel.level.offered_load_bps == 32000.0  # the medium's load when none is set
    fixed = RadioConfig(100.0, model="calibrated", calibration=synthetic, offered_load_bps=1.0)
    assert Channel(fixed, 0, 30000.0).level.offered_load_bps == 8000.0  # the config's wins


def test_beyond_the_largest_hop_count_delay_and_loss_only_grow(synthetic):
    level = synthetic.level(8000.0)
    hops = np.arange(1, 30)
    quantiles = level.quantiles(hops)
    assert (np.diff(quantiles[2:], axis=0) >= 0).all()  # from H = 3 on, every quantile grows
    assert (np.diff(quantiles, axis=1) >= 0).all()  # and stays a quantile function
    # each hop past H adds the mean per-hop growth of the measured hop counts
    growth = (level.quantiles_s[2] - level.quantiles_s[0]) / 2
    np.testing.assert_allclose(quantiles[3] - quantiles[2], np.maximum.accumulate(growth))
    survival = level.survival(hops)
    assert (np.diff(survival[2:]) < 0).all() and survival[-1] > 0
    assert survival[3] == pytest.approx(0.7 * np.sqrt(0.7 / 1.0))
    rng = np.random.default_rng(3)
    medians = [np.nanmedian(synthetic.sample(np.full(20_000, h), 8000.0, rng)) for h in
               (3, 4, 6, 10, 20)]  # fmt: skip
    assert all(a < b for a, b in zip(medians, medians[1:], strict=False))
    lost = [np.isnan(synthetic.sample(np.full(20_000, h), 8000.0, rng)).mean() for h in (3, 6, 12)]
    assert lost[0] < lost[1] < lost[2] < 1.0


# --------------------------------------------------------------------------- the simple model
def test_the_simple_model_is_the_default_and_draws_as_it_always_did():
    config = RadioConfig(100.0, hop_latency_s=0.002, jitter_s=0.001, loss=0.1, seed=11)
    assert config.model == "simple" and config.calibration is None
    channel = Channel(config, 0, 12000.0)  # a load changes nothing in the simple model
    assert channel.level is None
    rng = np.random.default_rng([config.seed, 0])
    for hops in (1, 4, 2, 9, 3) * 20:
        if rng.random() >= (1.0 - config.loss) ** hops:
            assert channel.transit(hops) is None
            continue
        per_hop = np.maximum(config.hop_latency_s + rng.uniform(-0.001, 0.001, hops), 0.0)
        assert channel.transit(hops) == float(per_hop.sum())
    with pytest.raises(ValueError, match="model must be one of simple, calibrated"):
        RadioConfig(100.0, model="ns3")


def test_the_calibrated_model_needs_its_table_and_the_fast_mode_loads_the_shipped_one(tmp_path):
    with pytest.raises(ValueError, match="needs its table"):
        RadioConfig(100.0, model="calibrated")
    config = radio_config(load_mission(mission(tmp_path, "radio: {model: calibrated}\n")))
    assert Path(config.calibration.source) == DEFAULT_CALIBRATION


def test_the_medium_offers_its_data_sources_load_to_the_channel(synthetic):
    from medium.ground_users import GroundUser

    users = (GroundUser(0.0, 0.0, 800.0), GroundUser(10.0, 0.0, 1600.0))
    assert offered_data_bps(users, 800.0, 9) == 800.0 * 9 + 2400.0
    assert offered_data_bps(users, None, 9) == 2400.0  # the medium process: no UAV data
    config = RadioConfig(100.0, model="calibrated", calibration=synthetic)
    model = MediumModel(config, np.zeros((1, 2)), np.ones((9, 2)), ground_users=users,
                        uav_data_bps=3200.0)  # fmt: skip
    assert model.channel.offered_load_bps == 3200.0 * 9 + 2400.0
    assert model.channel.level.offered_load_bps == 32000.0


# --------------------------------------------------------------------------- the mission
def mission(tmp_path: Path, radio: str, base: str = MINIMAL) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text(base + radio)
    return path


def test_radio_model_defaults_to_simple_and_takes_calibrated(tmp_path):
    assert load_mission(mission(tmp_path, "")).radio.model == "simple"
    calibrated_mission = load_mission(mission(tmp_path, "radio: {model: calibrated}\n"))
    assert calibrated_mission.radio.model == "calibrated"
    assert calibrated_mission.radio.calibration is None
    table = tmp_path / "tables" / "t.json"
    table.parent.mkdir()
    table.write_text(json.dumps(SYNTHETIC))
    text = "radio: {model: calibrated, calibration: tables/t.json}\n"
    chosen = load_mission(mission(tmp_path, text))
    assert chosen.radio.calibration == table.resolve()  # relative to the mission file
    config = radio_config(chosen)
    assert config.model == "calibrated" and Path(config.calibration.source) == table.resolve()
    setup = medium_setup(chosen)
    assert model_args(setup) == ["--model", "calibrated", "--calibration", str(table.resolve())]
    assert model_args(medium_setup(load_mission(mission(tmp_path, "")))) == []
    assert radio_config(load_mission(mission(tmp_path, ""))).model == "simple"


@pytest.mark.parametrize(
    ("radio", "key", "says"),
    [
        ("radio: {model: ns3}\n", "radio.model", "one of simple, calibrated, got 'ns3'"),
        ("radio: {model: 3}\n", "radio.model", "one of simple, calibrated"),
        ("radio: {model: calibrated, calibration: nowhere.json}\n", "radio.calibration",
         "a calibration table of gcs eval calibrate"),
        ("radio: {calibration: t.json}\n", "radio.calibration", "radio.model: calibrated"),
        ("radio: {model: calibrated, calibration: bad.json}\n", "radio.calibration",
         "levels[0].hops[0].delay_s: expected"),
    ],
)  # fmt: skip
def test_a_bad_radio_model_or_table_is_refused_on_one_line(tmp_path, gcs_main, radio, key, says):
    (tmp_path / "t.json").write_text(json.dumps(SYNTHETIC))
    bad = mutated(["levels", 0, "hops", 0, "delay_s"], [0.002, 0.001] * 4)
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    path = mission(tmp_path, radio)
    with pytest.raises(InputError) as caught:
        load_mission(path)
    assert caught.value.key_path == key and says in caught.value.expected
    code, out, err = gcs_main("mission", "plan", path)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and f"m.yaml: {key}: expected" in err and "Traceback" not in err


# --------------------------------------------------------------------------- the medium's flags
MEDIUM_ARGS = ["--count", "1", "--base-port", "15000", "--vehicle-ports", "15100",
               "--positions", "10,0", "--stations", "0,0", "--range", "100"]  # fmt: skip


def medium_config(*args: str):
    parser = medium_cli.build_parser()
    return medium_cli.config_from_args(parser.parse_args([*MEDIUM_ARGS, *args]))


def test_the_medium_takes_the_calibrated_model_and_its_table(tmp_path):
    assert medium_config().radio.model == "simple"
    shipped = medium_config("--model", "calibrated").radio
    assert shipped.model == "calibrated" and Path(shipped.calibration.source) == DEFAULT_CALIBRATION
    table = tmp_path / "t.json"
    table.write_text(json.dumps(SYNTHETIC))
    chosen = medium_config("--model", "calibrated", "--calibration", str(table)).radio
    assert chosen.calibration.source == str(table)


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--model", "ns3"], "--model"),
        (["--model", "calibrated", "--calibration", "/nowhere/t.json"], "--calibration"),
        (["--calibration", "t.json"], "--calibration"),
    ],
)
def test_the_medium_refuses_a_bad_model_or_table_on_one_line(capsys, args, flag):
    code = medium_cli.main([*MEDIUM_ARGS, *args])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and flag in err and "Traceback" not in err


# --------------------------------------------------------------------------- the fast mode
def test_the_fast_mode_flies_with_the_calibrated_medium(tmp_path):
    """The core mission with `radio.model: calibrated`: every UAV's data takes what the
    shipped table measured at that hop count (its lowest load: 4 UAVs x 800 bit/s), hundreds
    of microseconds for one hop, not the simple model's 2 ms a hop."""
    path = tmp_path / "core.yaml"
    path.write_text((MISSIONS / "core.yaml").read_text() + "radio: {model: calibrated}\n")
    run = fly_fast(plan_mission(load_mission(path)), FastOptions())
    assert run.run_json["completed"] is True
    packets = run.packets
    data = (packets["kind"] == KINDS.index("uav_data")) & np.isfinite(packets["delay_s"])
    hops, delays = packets["hops"][data], packets["delay_s"][data]
    assert data.sum() > 100 and set(hops.tolist()) >= {1, 2}
    level = load_calibration().levels[0]
    for hop_count in set(hops.tolist()):
        mine = delays[hops == hop_count]
        low, high = level.quantiles_s[hop_count - 1][[0, -1]]
        assert (mine >= low).all() and (mine <= high).all(), hop_count
    assert delays[hops == 1].max() < 0.001  # the simple model: 1 to 3 ms
    every = packets["delay_s"][np.isfinite(packets["delay_s"])]
    assert not np.allclose(every / packets["hops"][np.isfinite(packets["delay_s"])], 0.002)


# --------------------------------------------------------------------------- gcs eval calibrate
def test_each_uav_of_the_calibration_line_is_its_number_of_hops_from_a():
    plan = CalibrationPlan()
    scenario = line_scenario(plan, 800.0)
    graph = topology(scenario.base_stations, scenario.uav_positions[0, :, :2], plan.radio_range_m)
    assert graph.hops.tolist() == list(range(1, plan.max_hops + 1))
    assert (scenario.uav_positions == scenario.uav_positions[:1]).all()  # static
    assert scenario.packet_bytes == 200 and scenario.data_rate_bps == 800.0
    assert scenario.requests == ()
    # enough packets per source after the settling time, in each of the runs
    assert scenario.times[-1] >= plan.settle_s + plan.packets_per_source * plan.interval_s(800.0)
    assert len(set(plan.run_seeds(1)) | set(plan.run_seeds(2))) == 2 * plan.runs
    quick = line_scenario(QUICK_PLAN, 800.0)
    assert quick.fleet_size == 3 and quick.times[-1] == 30.0


def test_a_hop_count_row_reduces_its_packets():
    delays = np.array([0.001, 0.002, np.nan, 0.003, 0.004, np.nan, 0.005, 0.006, 0.007, 0.008])
    hops = np.where(np.isnan(delays), -1, 2)
    hops[0] = 3  # delivered over another hop count
    reduced = hop_row(delays, hops, 2)
    assert (reduced["sent"], reduced["lost"], reduced["loss_ratio"]) == (10, 2, 0.2)
    assert reduced["delay_s"][0] == 0.001 and reduced["delay_s"][-1] == 0.008
    assert reduced["delay_s"][QUANTILES.index(0.5)] == pytest.approx(0.0045)
    assert reduced["other_hops"] == 1
    nothing = hop_row(np.full(4, np.nan), np.full(4, -1), 5)
    assert nothing["loss_ratio"] == 1.0 and nothing["delay_s"] is None


def test_the_written_table_is_what_the_medium_reads():
    plan = CalibrationPlan(rates_bps=(800.0,), max_hops=2)
    rows = [hop_row(np.full(5, 0.001 * k), np.full(5, k), k) for k in (1, 2)]
    for reduced in rows:
        reduced.pop("other_hops")
    level = {"rate_bps_per_node": 800.0, "senders": 2, "offered_load_bps": 1600.0, "hops": rows}
    table = calibration_table([level], plan, NetOptions(), seed=3, ns3_version="3.44",
                              command="gcs eval calibrate --seed 3")  # fmt: skip
    text = table_json(table)
    assert json.loads(text) == table
    read = calibration_from_json(json.loads(text))
    assert read.levels[0].max_hops == 2 and read.made_by["command"].endswith("--seed 3")
    assert table["ns3"]["run_seeds"] == list(plan.run_seeds(3))


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--seed", "0"], "--seed"),
        (["--seed", "x"], "--seed"),
        (["--seed"], "--seed"),
        (["--out", "table.txt"], "--out"),
        (["--out", "/proc/fleetline-calibration.json"], "--out"),
        (["--out", "/nowhere/at/all/t.json"], "--out"),
        (["--quick", "--frobnicate"], "--frobnicate"),
    ],
)
def test_gcs_eval_calibrate_refuses_bad_flags_before_ns3(gcs_main, monkeypatch, args, flag):
    import gcs.netsim.ns3

    def no_ns3():
        raise AssertionError("ns-3 loaded before the flags were checked")

    monkeypatch.setattr(gcs.netsim.ns3, "load_ns3", no_ns3)
    code, out, err = gcs_main("eval", "calibrate", *args)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and flag in err and "Traceback" not in err
