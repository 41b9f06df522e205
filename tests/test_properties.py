"""Property tests: verdicts and paths do not depend on where, how big or how labelled."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.geometry import Similarity, rotation
from linkd.validator import validate

MECHANISMS = [classic.crank_rocker, classic.jansen_leg, classic.watt_six_bar,
              classic.stephenson_six_bar, classic.non_grashof_four_bar]  # fmt: skip


def _run(mech, n_angles=60):
    batch = LinkageBatch.from_mechanisms([mech])
    result = validate(batch, n_angles, keep_motion=True, backend="numpy")
    return int(result.status[0]), result.margin[0], result.end_effector_paths(batch)[0]


similarities = st.builds(
    lambda s, a, tx, ty: Similarity(s, rotation(a), np.array([tx, ty])),
    st.floats(0.01, 100),
    st.floats(-np.pi, np.pi),
    st.floats(-1e3, 1e3),
    st.floats(-1e3, 1e3),
)


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(MECHANISMS), similarities)
def test_invariant_under_translation_rotation_and_scaling(build, sim):
    mech = build()
    status, margin, path = _run(mech)
    moved_status, moved_margin, moved_path = _run(mech.transformed(sim))
    assert moved_status == status
    if status == 0:
        np.testing.assert_allclose(moved_margin, margin, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(moved_path, sim.apply(path), atol=1e-7 * sim.scale * 100)


@settings(max_examples=30, deadline=None)
@given(st.sampled_from(MECHANISMS), st.randoms(use_true_random=False))
def test_invariant_under_relabelling(build, rnd):
    mech = build()
    order = list(range(mech.n_nodes))
    rnd.shuffle(order)
    status, margin, path = _run(mech)
    got_status, got_margin, got_path = _run(mech.relabelled(order))
    assert got_status == status
    if status == 0:
        np.testing.assert_allclose(got_margin, margin, rtol=1e-9)
        np.testing.assert_allclose(got_path, path, atol=1e-9)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from(MECHANISMS[:4]), st.floats(-np.pi, np.pi))
def test_mirror_image_traces_the_mirrored_path_backwards(build, angle):
    mech = build()
    mirror = Similarity(1.0, rotation(angle, reflect=True))
    status, _, path = _run(mech)
    got_status, _, got_path = _run(mech.transformed(mirror))
    assert got_status == status == 0
    expected = mirror.apply(path)
    reversed_from_start = np.concatenate([expected[:1], expected[1:][::-1]])
    np.testing.assert_allclose(got_path, reversed_from_start, atol=1e-9)
