"""Target curves: the curve.csv reader (every accepted variant, every refusal), writer,
resampling, normalisation and the Chamfer and ordered distances."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from linkd.curves import (
    chamfer,
    chamfer_batch,
    curve_moments,
    cyclic_match,
    normalise,
    ordered_distance,
    ordered_distance_batch,
    read_curve,
    resample,
    write_curve,
)
from linkd.errors import InputError
from linkd.geometry import Similarity, rotation

EXAMPLES = Path(__file__).parents[1] / "assets" / "examples"
ANGLES = np.linspace(0, 2 * np.pi, 12, endpoint=False)
CURVE = np.c_[3 * np.cos(ANGLES) + 1.25, np.sin(ANGLES) - 0.5].round(6)


def _rows(sep=",", points=CURVE):
    return [f"{float(x)!r}{sep}{float(y)!r}" for x, y in points]


def _write(tmp_path, text, name="curve.csv", newline="\n"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


GOOD = {
    "comma with header": "x,y\n" + "\n".join(_rows()) + "\n",
    "semicolon, no header": "\n".join(_rows(";")),
    "tab with header": "X\tY\n" + "\n".join(_rows("\t")) + "\n",
    "whitespace, ragged": "x  y\n" + "\n".join(f"  {r.replace(',', '   ')} " for r in _rows()),
    "comma and space": "\n".join(_rows(", ")),
    "comments and blanks": "# my curve\n\nx,y # header\n"
    + "\n\n".join(f"{r}  # point" for r in _rows())
    + "\n# end\n",
    "closing point repeated": "x,y\n" + "\n".join([*_rows(), _rows()[0]]) + "\n",
    "decimal commas": "\n".join(r.replace(",", ";").replace(".", ",") for r in _rows()),
    "byte order mark": "\ufeffx,y\n" + "\n".join(_rows()),
    "trailing separators": "x,y,\n" + "\n".join(r + "," for r in _rows()),
}


@pytest.mark.parametrize("newline", ["\n", "\r\n"], ids=["LF", "CRLF"])
@pytest.mark.parametrize("variant", GOOD)
def test_reads_every_accepted_variant(tmp_path, variant, newline):
    points = read_curve(_write(tmp_path, GOOD[variant], newline=newline))
    assert points.dtype == np.float64
    np.testing.assert_array_equal(points, CURVE)


BAD = {
    "one column": ("x,y\n" + "\n".join(_rows()[:5]) + "\n3.5\n", "row 7: one column"),
    "three columns": ("\n".join([*_rows()[:4], "1,2,3", *_rows()[4:]]), "row 5: 3 columns"),
    "not a number": ("x,y\n" + "\n".join(_rows()[:6]) + "\n1.0,abc\n", "row 8: 'abc' is not a"),
    "second header": ("x,y\nx,y\n" + "\n".join(_rows()), "row 2: 'x' is not a number"),
    "nan": ("\n".join([*_rows()[:3], "nan,1", *_rows()[3:]]), "row 4: 'nan' is not finite"),
    "inf": ("# c\n" + "\n".join([*_rows(), "1,-inf"]), "row 14: '-inf' is not finite"),
    "overflow": ("\n".join([*_rows(), "1e999,0"]), "row 13: '1e999' is not finite"),
    "underscore": ("\n".join([*_rows(), "1_000,0"]), "row 13: '1_000' is not a number"),
    "empty": ("", "no points"),
    "header only": ("# nothing here\nx,y\n", "no points"),
    "too few points": ("x,y\n" + "\n".join(_rows()[:7]), "7 distinct points, need at least 8"),
    "too few distinct": ("\n".join(_rows()[:4] * 3), "4 distinct points"),
    "all equal": ("\n".join(_rows()[:1] * 20), "all points are equal"),
    "collinear": ("\n".join(f"{t},{2 * t + 1}" for t in ANGLES), "all points lie on one line"),
}


@pytest.mark.parametrize("case", BAD)
def test_refuses_bad_input_naming_file_and_row(tmp_path, case):
    text, expected = BAD[case]
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as refused:
        read_curve(path)
    message = str(refused.value)
    assert message.startswith(f"{path}: ")
    assert expected in message
    assert "\n" not in message


def test_refuses_unreadable_files(tmp_path):
    latin1 = tmp_path / "latin1.csv"
    latin1.write_bytes(b"x,y\n1,2\n# caf\xe9\n")
    cases = {
        tmp_path / "missing.csv": "cannot read",
        tmp_path: "cannot read",
        latin1: "row 3: not UTF-8 text",
    }
    for path, expected in cases.items():
        with pytest.raises(InputError, match=f"^{re.escape(str(path))}: {expected}"):
            read_curve(path)


def test_row_numbers_count_every_line_of_the_file(tmp_path):
    text = "# a\n\n# b\nx;y\n\n" + "\n".join(_rows(";")[:5]) + "\n\n1;two\n"
    with pytest.raises(InputError, match=r": row 12: 'two' is not a number$"):
        read_curve(_write(tmp_path, text, newline="\r\n"))


def test_example_curves_are_valid_and_small():
    files = sorted(EXAMPLES.glob("*.csv"))
    assert len(files) >= 4
    for path in files:
        points = read_curve(path)
        assert len(points) >= 60
        assert path.stat().st_size < 10_000


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=False)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(finite, finite), min_size=8, max_size=40, unique=True))
def test_written_curves_read_back_exactly(tmp_path_factory, rows):
    points = np.array(rows)
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    path = tmp_path_factory.mktemp("curves") / "out.csv"
    write_curve(path, points, comment="made by a test\nsecond line")
    if spread[1] <= 1e-6 * spread[0]:
        with pytest.raises(InputError, match="one line"):
            read_curve(path)
    else:
        np.testing.assert_array_equal(read_curve(path), points)


def test_write_curve_refuses_what_it_cannot_write(tmp_path):
    with pytest.raises(ValueError):
        write_curve(tmp_path / "a.csv", np.zeros((5, 3)))
    with pytest.raises(ValueError):
        write_curve(tmp_path / "a.csv", np.array([[0.0, np.nan]] * 8))
    assert not list(tmp_path.iterdir())


def _uneven_circle(n=400):
    u = np.linspace(0, 2 * np.pi, n, endpoint=False)
    t = u + 0.6 * np.sin(u)  # crowded on one side, sparse on the other
    return np.c_[np.cos(t), np.sin(t)]


def test_resampling_spaces_points_evenly_and_keeps_the_length():
    circle = _uneven_circle(4000)
    points = resample(circle, 200)
    assert points.shape == (200, 2)
    steps = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    assert steps.std() < 1e-3 * steps.mean()
    assert steps.sum() == pytest.approx(2 * np.pi, rel=1e-3)
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(points[0], circle[0])


def test_resampling_an_open_path_keeps_both_ends_and_skips_repeats():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    points = resample(path, 7, closed=False)
    np.testing.assert_array_equal(points[[0, -1]], path[[0, -1]])
    np.testing.assert_allclose(np.diff(points, axis=0).sum(axis=0), [1.0, 2.0])
    assert np.isfinite(points).all()
    with pytest.raises(ValueError):
        resample(np.ones((5, 2)))


similarities = st.builds(
    lambda s, a, r, tx, ty: Similarity(s, rotation(a, r), np.array([tx, ty])),
    st.floats(1e-3, 1e3),
    st.floats(-np.pi, np.pi),
    st.booleans(),
    st.floats(-1e3, 1e3),
    st.floats(-1e3, 1e3),
)


@settings(max_examples=40, deadline=None)
@given(similarities, st.booleans())
def test_normalisation_round_trip_and_frame(sim, by_arc_length):
    curve = sim.apply(_uneven_circle(50) * [2.0, 1.0] + [0.3, 0.0])
    normalised, back = normalise(curve, by_arc_length)
    np.testing.assert_allclose(back.apply(normalised), curve, atol=1e-9 * (1 + abs(curve).max()))
    centre, radius = curve_moments(normalised, by_arc_length)
    np.testing.assert_allclose(centre, 0.0, atol=1e-9)
    assert radius == pytest.approx(1.0, rel=1e-9)
    assert not back.reflects


def test_arc_length_moments_do_not_depend_on_the_sampling():
    offset = np.array([5.0, -2.0])
    uneven, even = _uneven_circle(3000) + offset, resample(_uneven_circle(3000), 500) + offset
    for points in (uneven, even):
        centre, radius = curve_moments(points)
        np.testing.assert_allclose(centre, [5.0, -2.0], atol=1e-4)
        assert radius == pytest.approx(1.0, abs=1e-4)
    assert np.linalg.norm(uneven.mean(axis=0) - [5.0, -2.0]) > 0.1  # what the points say
    moments = curve_moments(torch.tensor(np.stack([uneven, uneven * 2])))
    np.testing.assert_allclose(moments[1].numpy(), [1.0, 2.0], atol=1e-4)


def _cloud(seed, n):
    return np.random.default_rng(seed).normal(size=(n, 2))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 60), st.integers(1, 60))
def test_chamfer_numpy_and_torch_agree_and_are_symmetric(seed, n, m):
    a, b = _cloud(seed, n), _cloud(seed + 1, m)
    expected = chamfer(a, b)
    assert expected == pytest.approx(chamfer(b, a), rel=1e-12)
    batch = chamfer_batch(torch.tensor(np.stack([a, a])), torch.tensor(b))
    np.testing.assert_allclose(batch.numpy(), expected, rtol=1e-9)
    assert chamfer(a, a) == 0.0
    assert chamfer_batch(torch.tensor(a[None]), torch.tensor(a[None])).item() == 0.0


def test_chamfer_batch_is_differentiable():
    a = torch.tensor(_cloud(0, 30)[None], requires_grad=True)
    b = torch.tensor(_cloud(1, 40))
    chamfer_batch(a, b).sum().backward()
    assert torch.isfinite(a.grad).all() and a.grad.abs().sum() > 0
    a.grad = None
    chamfer_batch(a, a.detach()).sum().backward()  # zero distances stay finite
    assert torch.isfinite(a.grad).all()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(0, 199), st.booleans())
def test_ordered_distance_finds_the_shift_and_direction(seed, shift, reverse):
    a = resample(_cloud(seed, 9), 200)
    b = a[::-1] if reverse else a
    b = np.roll(b, -shift, axis=0)  # so that a[i] = b'[(i + k) % n] for some k
    found_shift, found_reverse, distance = cyclic_match(a, b)
    assert distance == pytest.approx(0.0, abs=1e-12)
    assert found_reverse == reverse
    b_dash = b[::-1] if found_reverse else b
    np.testing.assert_allclose(np.roll(b_dash, -found_shift, axis=0), a, atol=1e-12)
    if reverse:
        assert ordered_distance(a, b, allow_reverse=False) > 0.01


def test_ordered_distance_batch_matches_numpy():
    a = np.stack([resample(_cloud(s, 9), 50) for s in range(4)])
    b = np.stack([np.roll(resample(_cloud(s + 10, 9), 50), 7, axis=0) for s in range(4)])
    for allow_reverse in (True, False):
        expected = [ordered_distance(x, y, allow_reverse) for x, y in zip(a, b)]
        got = ordered_distance_batch(torch.tensor(a), torch.tensor(b), allow_reverse)
        np.testing.assert_allclose(got.numpy(), expected, rtol=1e-9)
    one = ordered_distance_batch(torch.tensor(a), torch.tensor(a[0]))
    assert one[0].item() == pytest.approx(0.0, abs=1e-12) and (one[1:] > 0).all()
