"""A step's infos as rows of the shared block: no pickling, nothing per worker on the driver.

Every Gymnasium MuJoCo task reports the same numeric scalars at every step (Ant-v5: nine,
one of them ``float32``). Through a worker's tail slot (:mod:`chronogym.vector.shared_step`)
they were pickled by the worker each step, and read, unpickled and joined by the driver
worker by worker: 10.7 µs of the driver's CPU per worker and step on a 2-core VM, the
largest part of its per-worker cost on such tasks; 1.7 µs as rows
(``benchmarks/results/compare_revisions_info_rows_synthetic.json``).

Here, when every env of a worker reports the keys and value types of one :class:`InfoSchema`,
the worker writes its envs' infos as records of the schema's NumPy structured dtype into its
envs' rows of the block's info area (:data:`INFO_ROW` bytes per env), and the schema's text
into its tail slot (status ``INFO_ROWS``). When every worker did so with one schema, the
driver checks their texts with one comparison and copies each key's column out of the area
(:func:`join_rows`): a few NumPy calls per key, none per worker.

The vector info is the one the columns path gives (:func:`~chronogym.vector.infos.join_infos`):
one array per key, of the dtype Gymnasium gives (``np.dtype(type(value))``), and an all-True
``_key`` mask. A step whose infos fit no one schema (keys that differ between envs, a value of
another type, an array, an episode end's ``final_obs``) travels in the tail slot as before.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from chronogym.vector.infos import PYTHON, InfoColumns, is_scalar_type, masked

INFO_ROW = 256  # bytes of the block's info area per env: 32 eight-byte scalars
TEXT = struct.Struct("<I")  # a node's rows (:func:`pack_node_rows`): the schema text's length


@dataclass(frozen=True)
class InfoSchema:
    """The keys and value types of one env's info, and the records that hold them."""

    keys: tuple[str, ...]
    kinds: tuple[str, ...]  # as InfoColumns names them ("py" for Python's own scalars)
    dtype: np.dtype  # a structured dtype of INFO_ROW bytes: one field per key
    packed: np.dtype  # the same fields with no padding after them (``used`` bytes)
    text: bytes  # the schema as both ends name it (a worker writes it to its tail slot)

    @property
    def used(self) -> int:
        """Bytes of a record that hold values (the rest of its INFO_ROW is padding)."""
        return self.packed.itemsize

    @classmethod
    def of_kinds(cls, keys: tuple[str, ...], kinds: tuple[str, ...]) -> InfoSchema | None:
        """The schema of these keys and kinds; None when their values overflow a row."""
        formats = [np.dtype(kind.removeprefix(PYTHON)) for kind in kinds]
        offsets, at = [], 0
        for fmt in formats:
            offsets.append(at)
            at += fmt.itemsize
        if at > INFO_ROW:
            return None
        fields = {"names": list(keys), "formats": formats, "offsets": offsets}
        dtype = np.dtype({**fields, "itemsize": INFO_ROW})
        packed = np.dtype({**fields, "itemsize": max(at, 1)})
        text = json.dumps([list(keys), list(kinds)], ensure_ascii=True).encode()
        return cls(keys, kinds, dtype, packed, text)

    @classmethod
    def parse(cls, text: bytes) -> InfoSchema:
        """The schema a worker named with ``text``."""
        keys, kinds = json.loads(text)
        schema = cls.of_kinds(tuple(keys), tuple(kinds))
        if schema is None:
            raise ValueError(f"an info schema over {INFO_ROW} bytes per env: {text!r}")
        return schema

    def columns(self, records: np.ndarray) -> InfoColumns:
        """Some envs' records as the columns a worker would have sent."""
        data = tuple(records[key].tobytes() for key in self.keys)
        return InfoColumns(len(records), self.keys, self.kinds, data)


def _scalar_kind(value: Any) -> str | None:
    """A value's kind as :func:`~chronogym.vector.infos.to_columns` names it, or None."""
    kind = type(value)
    if not is_scalar_type(kind):
        return None
    return (PYTHON if kind in (int, float, bool) else "") + np.dtype(kind).str


class RowWriter:
    """A worker's end: its envs' infos as records of one schema (the last one seen)."""

    def __init__(self) -> None:
        self.schema: InfoSchema | None = None
        self._types: tuple[type, ...] = ()

    def records(self, infos: list[dict[str, Any]]) -> np.ndarray | None:
        """The infos as records of :attr:`schema` (renewed when the first env's differs);
        None when they fit no one schema, or are all empty (then: the tail slot, as before)."""
        if not infos or not infos[0]:
            return None
        schema, rows = self.schema, []
        for info in infos:
            values = tuple(info.values())
            fits = schema is not None and tuple(info) == schema.keys
            if not (fits and tuple(map(type, values)) == self._types) and (
                rows or (schema := self._renew(info)) is None  # only the first env renews
            ):
                return None
            rows.append(values)
        assert schema is not None
        try:
            return np.array(rows, dtype=schema.dtype)
        except (OverflowError, ValueError, TypeError):  # e.g. an int beyond int64
            return None

    def _renew(self, info: dict[str, Any]) -> InfoSchema | None:
        kinds = tuple(_scalar_kind(value) for value in info.values())
        keys = tuple(info)
        if None in kinds or not all(isinstance(key, str) and key for key in keys):
            return None
        self.schema = InfoSchema.of_kinds(keys, kinds)  # type: ignore[arg-type]
        self._types = tuple(map(type, info.values())) if self.schema is not None else ()
        return self.schema


class RowReader:
    """The driver's end: the schemas named so far, by their text."""

    def __init__(self) -> None:
        self._schemas: dict[bytes, InfoSchema] = {}

    def schema(self, text: bytes) -> InfoSchema:
        """The schema named ``text`` (parsed once)."""
        if (schema := self._schemas.get(text)) is None:
            schema = self._schemas[text] = InfoSchema.parse(text)
        return schema


def records_in(area: np.ndarray, schema: InfoSchema, num_envs: int) -> np.ndarray:
    """The first ``num_envs`` rows of an info area (uint8) as records of ``schema`` (a view)."""
    return area[: num_envs * INFO_ROW].view(schema.dtype)


def pack_node_rows(schema: InfoSchema, records: np.ndarray) -> bytes:
    """A relay's records of one schema as bytes for the driver: the schema's text, then
    each record's ``used`` bytes (no padding)."""
    used = records.view(np.uint8).reshape(len(records), INFO_ROW)[:, : schema.used]
    return TEXT.pack(len(schema.text)) + schema.text + used.tobytes()


def unpack_node_rows(reader: RowReader, data: bytes, count: int) -> tuple[InfoSchema, np.ndarray]:
    """:func:`pack_node_rows`'s schema and ``count`` records (as a ``(count, used)`` uint8
    array)."""
    (size,) = TEXT.unpack_from(data)
    schema = reader.schema(bytes(data[TEXT.size : TEXT.size + size]))
    block = np.frombuffer(data, np.uint8, count * schema.used, TEXT.size + size)
    return schema, block.reshape(count, schema.used)


def join_rows(schema: InfoSchema, records: np.ndarray) -> dict[str, Any]:
    """Every env's infos, records of one schema (its ``dtype`` or ``packed``), as one
    Gymnasium vector info."""
    return masked(schema.keys, [records[key].copy() for key in schema.keys], len(records))
