"""Jansen walkers (linkd.classic.jansen_walker): the multi-leg mechanisms a user brings, built
as a Strandbeest is, and a mirrored pair of legs exported and verified."""

import numpy as np
import pytest

from linkd.classic import jansen_leg, jansen_walker
from linkd.export import export_mechanism
from linkd.topology import Status
from linkd.validator import validate_mechanism
from linkd.verify import verify_output


def test_one_leg_is_jansens_leg():
    assert np.array_equal(jansen_walker(1, mirrored=False).positions, jansen_leg().positions)


@pytest.mark.parametrize("phases, mirrored, joints", [(1, True, 14), (3, False, 20), (3, True, 36)])
def test_walkers_turn_fully_with_every_leg_on_the_crank(phases, mirrored, joints):
    walker = jansen_walker(phases, mirrored)
    assert walker.n_nodes == joints and validate_mechanism(walker)[0] == Status.VALID
    pins = {j for link in walker.links if 0 in link for j in link} - {0}
    assert len(pins) == phases  # every crank pin on the axle, as one plate
    foot = walker.positions[walker.end_effector]  # the first leg's; its mirror's, 5 joints on
    assert not mirrored or np.allclose(walker.positions[walker.end_effector + 5], foot * [-1, 1])


def test_an_even_number_of_crank_pins_is_refused():
    with pytest.raises(ValueError, match="odd number of pins, got 2"):
        jansen_walker(2)


def test_a_mirrored_pair_of_legs_is_built_and_verified(tmp_path):
    result = export_mechanism(jansen_walker(1, mirrored=True), tmp_path, {"mjcf", "stl"})
    assert sum(part["kind"] == "pin" for part in result.parts) == 12
    report = verify_output(tmp_path, write=False)
    assert report.passed, report.failed
