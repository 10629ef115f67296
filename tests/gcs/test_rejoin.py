"""The link policy alone (`gcs.flight.rejoin`), on simulated mission time: a lost UAV freezes
the formation; it resumes only after every such UAV has flown within its allowance for the
settle time; else everyone lands at the deadline, or at once when a UAV lands by itself; with
an operator, the operator decides."""

from __future__ import annotations

import numpy as np

from gcs.flight.rejoin import REJOIN_SETTLE_S, RejoinPolicy

ALLOWANCE = 1.5
WAIT = 10.0


def tick(
    policy, t, unavailable=None, errors=(0.2, 0.2, 0.2), frozen_by=None, holding=(), landing=()
):
    return policy.decide(
        t,
        unavailable or {},
        holding=frozenset(holding),
        landing=frozenset(landing),
        tracking_now=np.array(errors, float),
        tolerance_m=ALLOWANCE,
        frozen_by=frozen_by,
    )


def test_a_uav_lost_freezes_once_and_lands_everyone_at_the_deadline():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=False)
    first = tick(policy, 10.0, {1: "link lost"})
    assert first.freeze and not first.ask_operator and first.land is None
    assert not tick(policy, 15.0, {1: "link lost"}, frozen_by="link").freeze  # frozen already
    assert tick(policy, 19.9, {1: "link lost"}, frozen_by="link").land is None
    late = tick(policy, 20.0, {1: "link lost"}, frozen_by="link")
    assert late.land == "UAV 2: link lost for 10 s"


def test_the_formation_resumes_only_after_the_uav_settled_back_within_its_allowance():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=False)
    tick(policy, 10.0, {2: "link lost"})
    back = tick(policy, 12.0, {}, errors=(0.2, 0.2, 3.0), frozen_by="link")  # link back, far off
    assert not back.resume and back.land is None
    tick(policy, 13.0, {}, errors=(0.2, 0.2, 1.0), frozen_by="link")  # within: settling from 13
    assert not tick(policy, 13.0 + REJOIN_SETTLE_S - 0.1, {}, frozen_by="link").resume
    assert tick(policy, 13.0 + REJOIN_SETTLE_S, {}, frozen_by="link").resume
    assert policy.deadline is None and not policy.rejoining


def test_a_uav_drifting_off_again_restarts_its_settle_time_and_can_miss_the_deadline():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=False)
    tick(policy, 10.0, {0: "link lost"})
    tick(policy, 11.0, {}, frozen_by="link")
    tick(policy, 12.5, {}, errors=(2.0, 0.2, 0.2), frozen_by="link")  # off again
    assert not tick(policy, 13.5, {}, frozen_by="link").resume  # settling since 13.5
    drifting = tick(policy, 20.0, {}, errors=(2.0, 0.2, 0.2), frozen_by="link")
    assert drifting.land == "UAV 1: not back within its margin for 10 s"


def test_a_uav_landing_by_itself_lands_everyone_at_once():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=False)
    decision = tick(policy, 10.0, {1: "failsafe LAND"}, landing=(1,))
    assert decision.freeze and decision.land == "UAV 2 failsafe LAND"


def test_a_uav_holding_with_its_link_back_is_taken_back_to_guided_flight():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=False)
    decision = tick(policy, 10.0, {0: "holding", 2: "link lost"}, holding=(0,))
    assert decision.guided == (0,) and policy.rejoining == {0, 2}


def test_with_an_operator_the_operator_decides():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=True)
    decision = tick(policy, 10.0, {1: "link lost"})
    assert decision.freeze and decision.ask_operator
    assert policy.deadline is None and not policy.rejoining
    later = tick(policy, 100.0, {1: "link lost"}, frozen_by="link")
    assert later.land is None and not later.resume


def test_an_operator_speed_change_cancels_the_deadline():
    policy = RejoinPolicy(link_wait_s=WAIT, interactive=False)
    tick(policy, 10.0, {1: "link lost"})
    policy.operator_decided()
    # the operator's change unfroze the formation: the policy no longer owns it
    decision = tick(policy, 25.0, {}, frozen_by=None)
    assert decision.land is None and not decision.freeze and not policy.rejoining
