"""The data set on disk: manifest and shards, resuming, fixed splits, the loader, the CLI."""

import json

import numpy as np
import pytest

from linkd.cli import main
from linkd.dataset import FORMAT, MANIFEST, build, load_split, read_manifest, split_of
from linkd.errors import InputError

COUNT, SHARD = 40, 16


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    build(root, COUNT, seed=3, shard_size=SHARD)
    return root


def _everything(root):
    parts = [load_split(root, split) for split in ("train", "val", "test")]
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def test_manifest_and_shards_are_written(dataset):
    manifest = json.loads((dataset / MANIFEST).read_text())
    assert manifest["format"] == FORMAT and manifest["complete"]
    assert manifest["seed"] == 3 and manifest["count"] == COUNT
    assert [s["count"] for s in manifest["shards"]] == [16, 16, 8]
    assert sum(manifest["splits"]["fractions"].values()) == pytest.approx(1)
    assert manifest["generator"]["min_margin"] > 0
    for shard in manifest["shards"]:
        with np.load(dataset / shard["file"]) as data:
            assert len(data["graphs"]) == shard["count"]
            assert data["index"][0] == shard["first"]


def test_loader_returns_every_sample_once_with_the_documented_shapes(dataset):
    data = _everything(dataset)
    assert sorted(data["index"]) == list(range(COUNT))
    k = COUNT
    assert data["graphs"].shape == (k, 20, 24) and data["graphs"].dtype == np.float32
    assert data["curves"].shape == (k, 200, 2) and data["curves"].dtype == np.float32
    assert data["centre"].shape == (k, 2) and data["scale"].shape == (k,)
    assert data["n_nodes"].shape == (k,) and data["margin"].shape == (k,)
    assert (data["graphs"][:, :, 0].sum(1) == data["n_nodes"]).all()


def test_splits_are_deterministic_disjoint_and_roughly_as_asked():
    index = np.arange(100_000)
    names = split_of(index, seed=3)
    np.testing.assert_array_equal(names, split_of(index, seed=3))
    assert not np.array_equal(names, split_of(index, seed=4))
    share = {name: (names == name).mean() for name in ("train", "val", "test")}
    assert share["train"] == pytest.approx(0.98, abs=0.003)
    assert share["val"] == pytest.approx(0.01, abs=0.002)
    assert share["test"] == pytest.approx(0.01, abs=0.002)


def test_loaded_split_matches_the_hash(dataset):
    for split in ("train", "val", "test"):
        data = load_split(dataset, split)
        assert (split_of(data["index"], 3) == split).all()


def test_resume_keeps_complete_shards_and_remakes_missing_ones(tmp_path):
    build(tmp_path, 24, seed=1, shard_size=8)
    kept, lost = tmp_path / "shard-00000.npz", tmp_path / "shard-00001.npz"
    stamp, before = kept.stat().st_mtime_ns, lost.read_bytes()
    lost.unlink()
    (tmp_path / "shard-00002.npz").write_bytes(b"half a file")
    _, made = build(tmp_path, 24, seed=1, shard_size=8)
    assert made == 16
    assert kept.stat().st_mtime_ns == stamp
    assert lost.read_bytes() == before
    assert len(load_split(tmp_path, "train")["index"]) > 20


def test_a_different_data_set_in_the_folder_is_refused(tmp_path):
    build(tmp_path, 8, seed=1, shard_size=8)
    with pytest.raises(InputError, match="seed"):
        build(tmp_path, 8, seed=2, shard_size=8)
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not empty"):
        build(other, 8)


def test_unfinished_data_set_is_not_loaded(tmp_path):
    build(tmp_path, 8, seed=1, shard_size=8)
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    manifest["complete"] = False
    (tmp_path / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(InputError, match="unfinished"):
        read_manifest(tmp_path)


def test_cli_output_does_not_depend_on_the_worker_count(tmp_path, capsys):
    for workers in (1, 2):
        args = ["dataset", "--count", "24", "--shard-size", "8", "--seed", "5",
                "--workers", str(workers), "--out", str(tmp_path / f"w{workers}")]  # fmt: skip
        assert main(args) == 0
    assert "24 mechanisms in 3 shards" in capsys.readouterr().out
    one, two = _everything(tmp_path / "w1"), _everything(tmp_path / "w2")
    for key in one:
        np.testing.assert_array_equal(one[key], two[key])


def test_cli_refuses_bad_counts(tmp_path, capsys):
    assert main(["dataset", "--count", "0", "--out", str(tmp_path / "d")]) == 2
    assert "--count" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
