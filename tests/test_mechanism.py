"""mechanism.json reading and writing, and refusal of malformed files."""

import json

import numpy as np
import pytest

from linkd import classic
from linkd.errors import InputError
from linkd.mechanism import FORMAT, Mechanism


def test_round_trip_keeps_everything(tmp_path):
    mech = classic.jansen_leg().replace(units="cm", extra={"metrics": {"chamfer": 0.01}})
    path = tmp_path / "mechanism.json"
    mech.save(path)
    back = Mechanism.load(path)
    np.testing.assert_array_equal(back.positions, mech.positions)
    np.testing.assert_array_equal(back.fixed, mech.fixed)
    assert back.links == mech.links
    assert back.motor == mech.motor and back.end_effector == mech.end_effector
    assert back.units == "cm"
    assert back.extra == {"metrics": {"chamfer": 0.01}}


def test_contract_example_loads():
    data = {
        "format": FORMAT,
        "units": "mm",
        "nodes": [{"x": 0.0, "y": 0.0, "fixed": True}, {"x": 1.0, "y": 0.0, "fixed": False}],
        "links": [[0, 1]],
        "motor": [0, 1],
        "end_effector": 1,
    }
    mech = Mechanism.from_dict(data)
    assert mech.n_nodes == 2 and mech.links == ((0, 1),)


def _valid_dict():
    return classic.crank_rocker().to_dict()


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d.update(format="linkd-mechanism/9"), "'format'"),
        (lambda d: d.update(units="furlong"), "'units'"),
        (lambda d: d.update(nodes="many"), "'nodes'"),
        (lambda d: d["nodes"][2].update(x="1.0"), "nodes[2].x"),
        (lambda d: d["nodes"][1].update(fixed=1), "nodes[1].fixed"),
        (lambda d: d["links"].append([0, 9]), "links[5]"),
        (lambda d: d["links"].append([3, 3]), "itself"),
        (lambda d: d["links"].append([3, 1]), "duplicates"),
        (lambda d: d.update(motor=[0]), "'motor'"),
        (lambda d: d.update(motor=[1, 1]), "'motor'"),
        (lambda d: d.update(end_effector=True), "'end_effector'"),
        (lambda d: d.update(end_effector=5), "'end_effector'"),
        (lambda d: d.update(end_effector=0), "fixed joint: it traces no path"),
    ],
)
def test_malformed_content_is_refused_with_its_reason(change, message):
    data = _valid_dict()
    change(data)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")) as err:
        Mechanism.from_dict(data, source="m.json")
    assert str(err.value).startswith("m.json: ") and "\n" not in str(err.value)


@pytest.mark.parametrize("text", ["not json", '{"x": NaN}', "[1, 2]", ""])
def test_unreadable_files_are_refused(tmp_path, text):
    path = tmp_path / "m.json"
    path.write_text(text)
    with pytest.raises(InputError, match=r"m\.json"):
        Mechanism.load(path)


def test_infinite_coordinates_are_refused(tmp_path):
    data = _valid_dict()
    path = tmp_path / "m.json"
    path.write_text(json.dumps(data).replace('"x": 0.0', '"x": 1e999', 1))
    with pytest.raises(InputError, match=r"nodes\[0\].x"):
        Mechanism.load(path)
