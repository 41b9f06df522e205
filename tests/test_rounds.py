"""Later rounds grow designs the export can build by a joint (linkd.design.rounds)."""

import numpy as np
import pytest
from test_export_narrow import KNOTTED, SNARLED, STUBBORN, TANGLED

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.design.budget import around_width, search_width
from linkd.design.propose import Candidates
from linkd.design.rounds import DYAD_SLACK, around, with_coupler_point, with_dyad
from linkd.design.search import _buildable
from linkd.design.select import topology_key
from linkd.export import buildable
from linkd.validator import validate


def test_buildable_says_what_export_would_do():
    assert buildable(TANGLED)  # at a narrower width
    assert not buildable(TANGLED, quick=True)  # which the quick check does not try
    assert buildable(SNARLED)  # on a turntable, where nothing else builds it
    assert buildable(KNOTTED)  # a link on a sheave (else its crank split on a bracket)
    assert not buildable(KNOTTED, quick=True)
    assert buildable(classic.crank_rocker(), quick=True)
    assert not buildable(STUBBORN)


def test_rounds_pass_over_a_better_design_that_cannot_be_built():
    batch = LinkageBatch.from_mechanisms([STUBBORN, classic.crank_rocker()])
    candidates = Candidates(batch, np.array([0.1, 0.2]))  # the refused one ranks first
    check = _buildable()
    nearby = around(candidates, count=2, copies=3, spread=0.1, seed=0, buildable=check)
    assert len(nearby) == 3
    plain = batch.subset(np.array([1]))
    n = int(plain.valid.sum())
    for row in range(len(nearby)):  # the crank-rocker, grown by a joint or a dyad
        assert nearby.valid[row].sum() in (n + 1, n + 2)
        assert (nearby.adjacency[row, :n, :n] == plain.adjacency[0, :n, :n]).all()
        assert np.allclose(nearby.positions[row, :n], plain.positions[0, :n])
    # Without the check, the refused design's neighbourhood is searched first.
    unchecked = around(candidates, count=2, copies=3, spread=0.1, seed=0)
    refused = topology_key(batch, 0)  # with no room to grow: jittered
    assert any(topology_key(unchecked, row) == refused for row in range(len(unchecked)))


def test_no_round_when_nothing_can_be_built():
    candidates = Candidates(LinkageBatch.from_mechanisms([STUBBORN]), np.array([0.1]))
    assert len(around(candidates, 4, 3, 0.1, 0, _buildable())) == 0


def test_a_grown_joint_is_a_coupler_point_and_the_end_effector():
    grown = with_coupler_point(_padded_crank_rocker(64), np.random.default_rng(0))
    assert (grown.end_effector == 5).all() and (grown.valid.sum(1) == 6).all()
    motion = validate(grown, keep_motion=True, backend="numpy")  # float64
    assert motion.valid.all()  # rigid with a link: valid wherever it starts
    xy = np.stack([motion.motion.x, motion.motion.y], -1)  # (B, N, T, 2)
    for row in range(len(grown)):
        parents = np.flatnonzero(grown.adjacency[row, 5])
        assert len(parents) == 2 and not grown.fixed[row, parents].any()
        assert grown.adjacency[row, parents[0], parents[1]]
        for p in parents:  # at a constant distance from both ends of its link
            d = np.linalg.norm(xy[row, 5] - xy[row, p], axis=-1)
            assert np.ptp(d) < 1e-9 * max(d.mean(), 1.0)
    # Half start near the end effector's old path, the rest anywhere about a link.
    old = np.linalg.norm(grown.positions[:, 5] - grown.positions[:, 4], axis=-1)
    assert 0.2 < (old < 0.5).mean() < 0.9


def test_a_dyad_hangs_the_end_effector_on_a_new_loop_near_its_old_path():
    batch = _padded_crank_rocker(64)
    before = validate(batch, keep_motion=True, backend="numpy")
    paths = np.stack([before.motion.x, before.motion.y], -1)  # (B, N, T, 2)
    grown = with_dyad(batch, paths, np.random.default_rng(0))
    assert len(grown) == 64 and (grown.end_effector == 6).all() and (grown.valid.sum(1) == 7).all()
    after = validate(grown, keep_motion=True, backend="numpy")
    assert after.valid.all()
    # Each transmission angle of the new dyad stays within acos(DYAD_SLACK) of a right angle
    # (up to the sampling of the revolution), so it is far from locking.
    assert after.margin.min() > 0.02
    xy = np.stack([after.motion.x, after.motion.y], -1)
    for row in range(len(grown)):
        assert set(np.flatnonzero(grown.adjacency[row, 6])) == {4, 5}  # old end effector, A
        q, r = np.flatnonzero(grown.adjacency[row, 5, :5])  # the link A hangs on
        for p in (q, r):  # A is a coupler point of its link, on another body than E's
            assert np.ptp(np.linalg.norm(xy[row, 5] - xy[row, p], axis=-1)) < 1e-9
        assert not (grown.adjacency[row, 4, q] and grown.adjacency[row, 4, r])
        cos = _cosines(xy[row, 6], xy[row, 4], xy[row, 5])
        assert np.abs(cos).max() <= DYAD_SLACK + 0.01 and np.ptp(cos) > 0.5  # a loop that moves
    # The new end effector starts near the old path: within half its RMS radius on most.
    old = xy[:, 4] - xy[:, 4].mean(1, keepdims=True)
    radius = np.sqrt((old**2).sum(-1).mean(1))
    off = np.linalg.norm(xy[:, 6] - xy[:, 4], axis=-1).max(1) / radius
    assert np.median(off) < 0.5 and off.min() < 0.15


def _cosines(apex: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(T,) cosine of the angle at `apex` between its links to `first` and `second`."""
    u, v = first - apex, second - apex
    return (u * v).sum(-1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))


@pytest.mark.parametrize("max_joints", [5, None])
def test_designs_with_no_room_to_grow_are_jittered(max_joints):
    # Five joints: at the limit asked for, or padded to no more than that.
    batch = _padded_crank_rocker(1, 5 if max_joints is None else 20)
    candidates = Candidates(batch, np.array([0.1]))
    nearby = around(candidates, 1, 6, 0.1, seed=0, max_joints=max_joints)
    assert len(nearby) == 6
    assert all(topology_key(nearby, row) == topology_key(batch, 0) for row in range(6))
    assert not np.allclose(nearby.positions, batch.positions)


def _padded_crank_rocker(count: int, joints: int = 20) -> LinkageBatch:
    graphs = np.full((count, joints, 24), -1.0, np.float32)
    graphs[:, :5] = LinkageBatch.from_mechanisms([classic.crank_rocker()]).to_graphs()[0]
    return LinkageBatch.from_graphs(graphs)


def test_a_longer_budget_searches_wider_unless_told():
    assert search_width(30, None, None) == (6, 1024, 48)  # the defaults
    assert search_width(120, None, None) == (30, 4096, 96)  # rounds until the deadline
    assert search_width(120, 1, 10, 4) == (1, 10, 4)
    # An open or timed stroke, which has no polish, has more rounds.
    assert search_width(30, None, None, stroke=True) == (8, 1024, 48)
    assert search_width(120, None, None, stroke=True) == (32, 4096, 96)
    assert search_width(30, 3, None, 20, stroke=True) == (3, 1024, 20)
    assert around_width(30, None) == 4 and around_width(120, None) == 16
    assert around_width(120, 2) == 2
