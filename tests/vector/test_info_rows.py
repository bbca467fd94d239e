"""Infos as rows of the shared block (chronogym.vector.info_rows): the vector info is the one
the columns path and Gymnasium give, and infos that fit no one schema are refused."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from info_envs import InfoEnv

from chronogym.vector.info_rows import (
    INFO_ROW,
    InfoSchema,
    RowReader,
    RowWriter,
    join_rows,
    pack_node_rows,
    records_in,
    unpack_node_rows,
)
from chronogym.vector.infos import batch_infos, join_infos, to_columns


def env_infos(count: int, steps: int = 3) -> list[dict]:
    """The infos of ``count`` InfoEnvs after ``steps`` steps: float, float32, int and bool."""
    infos = []
    for i in range(count):
        env = InfoEnv(i)
        env.reset(seed=i)
        for _ in range(steps):
            info = env.step(np.full(1, 0.1 * i, np.float32))[4]
        infos.append(info)
    return infos


def laid_out(infos_per_worker: list[list[dict]]) -> tuple[InfoSchema, np.ndarray, int]:
    """Each worker's records written to its envs' rows of one info area, as workers do."""
    total = sum(len(infos) for infos in infos_per_worker)
    area = np.zeros(total * INFO_ROW, np.uint8)
    at, schema = 0, None
    for infos in infos_per_worker:
        writer = RowWriter()
        records = writer.records(infos)
        assert records is not None and writer.schema is not None
        area[at * INFO_ROW : (at + len(infos)) * INFO_ROW] = np.frombuffer(records, np.uint8)
        at += len(infos)
        schema = RowReader().schema(writer.schema.text)  # the driver parses the text
    assert schema is not None
    return schema, area, total


def test_rows_give_the_vector_info_of_columns_and_of_gymnasium():
    parts = [env_infos(2), env_infos(3)]
    schema, area, total = laid_out(parts)
    joined = join_rows(schema, records_in(area, schema, total))
    columns = join_infos([to_columns(p) for p in parts], [2, 3])
    gymnasium = batch_infos(parts[0] + parts[1])
    assert data_equivalence(joined, columns, exact=True)
    assert list(joined) == list(gymnasium)
    for key in ("x", "x32", "t", "done_soon"):
        assert joined[key].dtype == gymnasium[key].dtype, key
        assert joined[key].tolist() == gymnasium[key].tolist(), key
        assert joined["_" + key].all() and joined[key].flags.writeable


def test_a_workers_rows_are_the_columns_it_would_have_sent():
    infos = env_infos(3)
    schema, area, total = laid_out([infos])
    records = records_in(area, schema, total)
    assert schema.columns(records) == to_columns(infos)
    assert [type(v) for v in schema.columns(records).per_env()[0].values()] == [
        float,
        np.float32,
        int,
        bool,
    ]


@pytest.mark.parametrize(
    "infos",
    [
        [{}, {}],  # nothing to say: no tail at all
        [{"a": 1}, {"b": 1}],  # different keys
        [{"a": 1.0, "b": 2.0}, {"b": 2.0, "a": 1.0}],  # the same keys in another order
        [{"a": 1}, {"a": 1.5}],  # one key, two types
        [{"a": np.bool_(True)}, {"a": np.bool_(False)}],  # Gymnasium: an object array
        [{"a": np.zeros(2)}, {"a": np.ones(2)}],  # arrays
        [{"a": 2**70}, {"a": 1}],  # beyond int64
        [{1: 1.0}],  # a key that is not a name
        [{f"k{i}": float(i) for i in range(INFO_ROW // 8 + 1)}],  # over a row's bytes
    ],
)
def test_infos_that_fit_no_one_schema_are_refused(infos):
    assert RowWriter().records(infos) is None


def test_a_new_schema_when_the_keys_change():
    writer = RowWriter()
    assert writer.records([{"a": 1.0}]) is not None
    first = writer.schema
    records = writer.records([{"a": 1.0, "b": np.float32(2)}])
    assert records is not None and writer.schema != first
    assert writer.schema.kinds == ("py<f8", "<f4")
    assert InfoSchema.parse(writer.schema.text) == writer.schema


def test_a_nodes_rows_travel_without_padding_and_join_the_same():
    """A relay packs its node's records (the schema's text, then the bytes that hold values);
    the driver's records of the packed dtype join to the same vector info."""
    infos = env_infos(3)
    schema, area, total = laid_out([infos])
    data = pack_node_rows(schema, records_in(area, schema, total))
    assert len(data) < total * INFO_ROW
    got, block = unpack_node_rows(RowReader(), data, total)
    assert got == schema and block.shape == (total, schema.used)
    packed = np.ascontiguousarray(block).view(schema.packed).reshape(total)
    assert data_equivalence(
        join_rows(got, packed), join_rows(schema, records_in(area, schema, total)), exact=True
    )
