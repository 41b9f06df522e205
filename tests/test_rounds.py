"""Later rounds search around designs the export can build (linkd.design.rounds)."""

import numpy as np
from test_export_narrow import KNOTTED, SNARLED, TANGLED

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.design.propose import Candidates
from linkd.design.rounds import around
from linkd.design.search import _buildable, search_width
from linkd.design.select import topology_key
from linkd.export import buildable


def test_buildable_says_what_export_would_do():
    assert buildable(TANGLED)  # at a narrower width
    assert not buildable(TANGLED, quick=True)  # which the quick check does not try
    assert not buildable(SNARLED)  # refused at every width, straight, bent or split
    assert buildable(KNOTTED)  # with its crank split on a ground bracket
    assert not buildable(KNOTTED, quick=True)
    assert buildable(classic.crank_rocker(), quick=True)


def test_rounds_pass_over_a_better_design_that_cannot_be_built():
    batch = LinkageBatch.from_mechanisms([SNARLED, classic.crank_rocker()])
    candidates = Candidates(batch, np.array([0.1, 0.2]))  # the refused one ranks first
    check = _buildable()
    nearby = around(candidates, count=2, copies=3, spread=0.1, seed=0, buildable=check)
    assert len(nearby) == 3
    plain = topology_key(batch, 1)
    assert all(topology_key(nearby, row) == plain for row in range(len(nearby)))
    # Without the check, the refused design's neighbourhood is searched first.
    unchecked = around(candidates, count=2, copies=3, spread=0.1, seed=0)
    assert topology_key(unchecked, 0) == topology_key(batch, 0)


def test_no_round_when_nothing_can_be_built():
    candidates = Candidates(LinkageBatch.from_mechanisms([SNARLED]), np.array([0.1]))
    assert len(around(candidates, 4, 3, 0.1, 0, _buildable())) == 0


def test_a_longer_budget_searches_wider_unless_told():
    assert search_width(30, None, None) == (3, 1024, 48)  # the defaults
    assert search_width(120, None, None) == (15, 4096, 96)  # rounds until the deadline
    assert search_width(120, 1, 10, 4) == (1, 10, 4)
    # An open or timed stroke has one round and refines three times as many designs in it.
    assert search_width(30, None, None, stroke=True) == (1, 1024, 144)
    assert search_width(30, 3, None, 20, stroke=True) == (1, 1024, 20)
