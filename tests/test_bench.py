"""`linkd bench`: the targets run and print their figures; the compiled kernel agrees with eager."""

import re
import shutil

import numpy as np
import pytest
import torch

from linkd.batch import LinkageBatch
from linkd.cli import main
from linkd.generator import GeneratorSettings, generate
from linkd.validator import validate


def test_generator_target_prints_its_throughput(capsys):
    assert main(["bench", "generator", "--count", "32", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "32 valid curated mechanisms" in out and "mechanisms/s" in out


def test_kinematics_target_prints_its_throughput(capsys):
    args = ["bench", "kinematics", "--batch", "40", "--repeat", "1", "--eager", "--chunk", "16"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "40 mechanisms x 20 joints" in out and "valid          100.0%" in out


def test_export_target_exports_and_verifies_unseen_mechanisms(capsys):
    assert main(["bench", "export", "--count", "4", "--seed", "5", "--max-joints", "9"]) == 0
    out = capsys.readouterr().out
    assert "4 random mechanisms of 5 to 9 joints" in out
    outcomes = ("verified", "refused", "failed verification")
    counts = [int(line.split()[-1]) for line in out.splitlines()
              if line.strip().startswith(outcomes)]  # fmt: skip
    assert sum(counts) == 4 and "failed verification" not in out
    slowest = next(line for line in out.splitlines() if "export + verify seconds" in line)
    assert re.search(r"max [0-9.]+ \(no\. [0-3]\)$", slowest)  # named, to be rebuilt


BAD_JOINTS = [["--min-joints", "4"], ["--min-joints", "9", "--max-joints", "8"],
              ["--max-joints", "21"]]  # fmt: skip


@pytest.mark.parametrize("bounds", BAD_JOINTS)
def test_export_target_refuses_joint_counts_it_cannot_generate(capsys, bounds):
    assert main(["bench", "export", "--count", "1", *bounds]) == 2
    err = capsys.readouterr().err
    assert "5 <= --min-joints <= --max-joints <= 20" in err and len(err.strip().splitlines()) == 1


@pytest.mark.skipif(not shutil.which("g++"), reason="torch.compile needs a C++ compiler")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # raised inside torch's compiler
def test_compiled_kinematics_match_eager():
    graphs = generate(24, 2, GeneratorSettings(min_nodes=12)).graphs
    batch = LinkageBatch.from_graphs(graphs)
    eager = validate(batch, keep_motion=True, chunk=16)
    with torch.no_grad():
        fused = validate(batch, keep_motion=True, chunk=16, compiled=True)
    np.testing.assert_array_equal(fused.status, eager.status)
    np.testing.assert_allclose(fused.margin, eager.margin, rtol=1e-4)
    np.testing.assert_allclose(fused.motion.x, eager.motion.x, atol=1e-4)
    np.testing.assert_allclose(fused.motion.y, eager.motion.y, atol=1e-4)
