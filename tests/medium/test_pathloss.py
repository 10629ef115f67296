"""Links through buildings under 3GPP TR 38.901 UMi-Street Canyon (`medium.pathloss`): the
published formulas at hand-computed points, the NLOS range as the inverse of the budget, the
medium's topology with it, and the mission key."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from medium.pathloss import (
    ThroughBuildings,
    los_path_loss_db,
    nlos_path_loss_db,
    nlos_range_m,
)
from medium.radio import topology
from planner.obstacles import Obstacles
from planner.sight import Sight

BLOCK = Obstacles(polygons=(np.array([[40.0, -20.0], [60.0, -20.0], [60.0, 20.0], [40.0, 20.0]]),))


def test_the_published_formulas_at_hand_computed_points():
    # TR 38.901 Table 7.4.1-1 at 100 m, 2.4 GHz: 32.4 + 21 * 2 + 20 log10(2.4)
    assert float(los_path_loss_db(100.0, 2.4)) == pytest.approx(82.004, abs=1e-3)
    # 35.3 * 2 + 22.4 + 21.3 log10(2.4) - 0.3 (1.5 - 1.5)
    assert float(nlos_path_loss_db(100.0, 2.4, 1.5)) == pytest.approx(101.098, abs=1e-3)
    # heights are clamped to the model's 22.5 m: 40 m counts as 22.5 m
    assert float(nlos_path_loss_db(100.0, 2.4, 40.0)) == pytest.approx(101.098 - 6.3, abs=1e-3)
    # never below the LOS loss (short distances), and 10 m is the shortest distance
    assert float(nlos_path_loss_db(10.0, 2.4, 22.5)) >= float(los_path_loss_db(10.0, 2.4))
    assert float(los_path_loss_db(1.0, 2.4)) == float(los_path_loss_db(10.0, 2.4))


@given(
    range_m=st.floats(30.0, 2000.0),
    frequency=st.floats(0.5, 100.0),
    height=st.floats(1.5, 60.0),
)
def test_the_nlos_range_spends_exactly_the_budget_of_a_los_link_at_the_radio_range(
    range_m, frequency, height
):
    reach = nlos_range_m(range_m, frequency, height)
    assert 0 < reach <= range_m
    budget = float(los_path_loss_db(range_m, frequency))
    if reach < range_m and reach > 10.0:
        assert float(nlos_path_loss_db(reach, frequency, height)) == pytest.approx(budget)
    assert float(nlos_path_loss_db(reach * 1.01, frequency, height)) > budget - 1e-9


def test_at_our_radio_ranges_a_link_through_a_building_reaches_about_a_third_as_far():
    assert nlos_range_m(150.0, 2.4, 40.0) == pytest.approx(55.3, abs=0.1)
    assert nlos_range_m(220.0, 2.4, 30.0) == pytest.approx(69.4, abs=0.1)
    assert math.isinf(nlos_range_m(math.inf, 2.4, 20.0))


def test_the_medium_keeps_a_short_link_through_a_building_and_cuts_a_long_one():
    """A station and two UAVs, each behind the block: the one 30 m from the station's far
    wall side (a 70 m chord through the block) is cut at an NLOS range of 55 m, the one whose
    chord through the block is 50 m long is kept; with the model off (`cut`) both are cut."""
    stations = np.array([[30.0, 0.0]])
    uavs = np.array([[100.0, 0.0], [80.0, 5.0]])  # chords of 70 m and 50.2 m through it
    sight = Sight(BLOCK)
    nlos = topology(stations, uavs, 150.0, sight=ThroughBuildings(sight, 55.3))
    cut = topology(stations, uavs, 150.0, sight=ThroughBuildings(sight, 0.0))
    assert nlos.hears_station[:, 0].tolist() == [False, True]
    assert cut.hears_station[:, 0].tolist() == [False, False]
    # the two UAVs see each other (the chord misses the block) under both
    assert nlos.hears_uav[0, 1] and cut.hears_uav[0, 1]
    assert nlos.hops.tolist() == [2, 1] and cut.hops.tolist() == [-1, -1]


@pytest.mark.parametrize(
    ("value", "model"),
    [(True, "3gpp-umi"), (False, None), ("cut", "cut"), ("3gpp-umi", "3gpp-umi")],
)
def test_the_mission_key_names_the_model(tmp_path, value, model):
    from gcs.mission import load_mission
    from tests.flying import mission_file

    mission = load_mission(mission_file(tmp_path, radio={"buildings": value}))
    assert mission.radio.buildings == model
    assert mission.radio.frequency_ghz == 2.4


@pytest.mark.parametrize(
    ("radio", "key"),
    [({"buildings": "walls"}, "radio.buildings"), ({"frequency_ghz": 300}, "radio.frequency_ghz")],
)
def test_a_bad_model_or_frequency_is_refused_naming_the_key(tmp_path, radio, key):
    from gcs.errors import InputError
    from gcs.mission import load_mission
    from tests.flying import mission_file

    with pytest.raises(InputError, match=key):
        load_mission(mission_file(tmp_path, radio=radio))
