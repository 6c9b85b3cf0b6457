"""Cumulative tables (accal.io.merge) and chunked writing (accal.io.chunked)."""

import numpy as np
import pandas as pd
import pytest

from accal.errors import ValidationError
from accal.io.chunked import chunked_table_writer
from accal.io.merge import merge_table
from accal.io.writers import read_table_metadata, write_table


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_merge_replaces_by_key_and_grows_the_schema(tmp_path, fmt):
    path = tmp_path / f"t.{fmt}"

    def meta(old):
        return {"runs": old.get("runs", 0) + 1}

    a = {"source": np.array(["a", "a", "b"], object), "axis": np.array(["x", "y", "x"], object),
         "v": np.array([1.0, 2.0, 3.0])}  # fmt: skip
    merge_table(
        path, a, key=("source", "axis"), sort=("source", "axis"), units={"v": "m"}, meta=meta
    )
    # replace (a, y), add (c, x) with a new column w; (a, x) and (b, x) stay
    b = {"source": np.array(["c", "a"], object), "axis": np.array(["x", "y"], object),
         "v": np.array([5.0, 20.0]), "w": np.array([7, 8])}  # fmt: skip
    merge_table(
        path, b, key=("source", "axis"), sort=("source", "axis"), units={"w": "s"}, meta=meta
    )
    df = pd.read_parquet(path) if fmt == "parquet" else pd.read_csv(path)  # pandas' defaults
    assert df[["source", "axis"]].values.tolist() == [
        ["a", "x"],
        ["a", "y"],
        ["b", "x"],
        ["c", "x"],
    ]
    assert df.v.tolist() == [1.0, 20.0, 3.0, 5.0]
    assert df.w.isna().tolist() == [True, False, True, False]
    units, m = read_table_metadata(path)
    assert units == {"v": "m", "w": "s"} and m == {"runs": 2}
    # re-running a key with fewer rows drops the old ones; an all-null column disappears
    merge_table(path, {"source": np.array(["c"], object), "axis": np.array(["z"], object),
                       "v": np.array([0.0])}, key=("source",), sort=("source", "axis"))  # fmt: skip
    merge_table(path, {"source": np.array(["a"], object), "axis": np.array(["x"], object),
                       "v": np.array([9.0])}, key=("source",), sort=("source", "axis"))  # fmt: skip
    df = pd.read_parquet(path) if fmt == "parquet" else pd.read_csv(path)  # pandas' defaults
    assert df[["source", "axis", "v"]].values.tolist() == [
        ["a", "x", 9.0],
        ["b", "x", 3.0],
        ["c", "z", 0.0],
    ]
    assert "w" not in df and read_table_metadata(path)[0] == {"v": "m"}


def test_merge_refuses_a_table_without_the_key(tmp_path):
    path = tmp_path / "periods.parquet"
    write_table({"period": np.arange(3)}, path)
    with pytest.raises(ValidationError, match=r"periods\.parquet: existing table has no source"):
        merge_table(path, {"source": np.array(["r"], object)}, key=("source",))


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_chunked_writer_is_atomic_and_round_trips(tmp_path, fmt):
    path = tmp_path / f"big.{fmt}"
    with chunked_table_writer(path, units={"t": "s", "unused": "m"}, meta={"k": 1}) as w:
        for i in range(3):
            w.write({"t": np.arange(4.0) + 4 * i, "n": np.arange(4) + 4 * i})
        assert not path.exists()  # appears only when the block ends
    df = pd.read_parquet(path) if fmt == "parquet" else pd.read_csv(path)  # pandas' defaults
    np.testing.assert_array_equal(df.t, np.arange(12.0))
    assert read_table_metadata(path) == ({"t": "s"}, {"k": 1})
    with pytest.raises(RuntimeError), chunked_table_writer(tmp_path / f"bad.{fmt}") as w:
        w.write({"t": np.arange(2.0)})
        raise RuntimeError("simulated crash")
    # nothing of the crashed one; a CSV's units are in its sidecar
    want = [path.name] + ([f"{path.name}-metadata.json"] if fmt == "csv" else [])
    assert sorted(p.name for p in tmp_path.iterdir()) == want
