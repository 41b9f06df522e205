"""`linkd trace`: the end effector's path as CSV, and one-line refusals of where it cannot go."""

from pathlib import Path

import numpy as np
import pytest

from linkd.cli import main
from linkd.commands.trace import end_effector_path
from linkd.mechanism import Mechanism

EXAMPLES = Path(__file__).resolve().parents[1] / "assets" / "examples"
MECH = str(EXAMPLES / "crank_rocker.json")


def test_trace_writes_the_path_as_csv(tmp_path):
    out = tmp_path / "path.csv"
    assert main(["trace", MECH, "--angles", "50", "-o", str(out)]) == 0
    written = np.loadtxt(out, delimiter=",", skiprows=1)
    expected = end_effector_path(Mechanism.load(MECH), 50)
    assert written.shape == (50, 2) and np.allclose(written, expected, atol=1e-6)


@pytest.mark.parametrize("where", ["folder", "under_a_file", "out_of_reach"])
def test_trace_refuses_an_output_it_cannot_write(tmp_path, capsys, where):
    (tmp_path / "afile").write_text("")
    output = {"folder": str(tmp_path), "under_a_file": str(tmp_path / "afile" / "x.csv"),
              "out_of_reach": "/proc/x.csv"}[where]  # fmt: skip
    assert main(["trace", MECH, "-o", output]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and output in err[0]
    assert [p.name for p in tmp_path.iterdir()] == ["afile"]
