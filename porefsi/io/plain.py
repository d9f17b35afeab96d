"""Plain-array encoding of state objects, for checkpoints that load without pickles.

A value is stored under a name as numeric arrays (in a dict that becomes an ``.npz``) plus a
JSON-able tag (in a metadata dict), so the file loads with ``numpy.load(allow_pickle=False)``
and cannot run code. Numbers travel as 0-d arrays, so every float (NaN and infinities too)
comes back bit for bit. Supported values: ndarrays of a numeric or bool dtype, None, bool, int,
float, str, numpy scalars, CSR sparse matrices (``scipy.sparse`` matrix or array), tuples or
lists of ndarrays (e.g. one index array per pore) and tuples of ints (shapes). Anything else is
a ``TypeError``: a state object that grew an attribute of another type must be taught here, not
silently dropped.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["put", "get", "put_fields", "get_fields", "put_dataclass"]


def _key(prefix: str, name: str) -> str:
    return f"{prefix}.{name}"


def put(prefix: str, name: str, value: Any, arrays: dict, tags: dict) -> None:
    """Store ``value`` as arrays ``arrays[prefix.name...]`` and its tag ``tags[name]``.

    Raises
    ------
    TypeError
        A value of a type this module does not encode (a programming error, not a user's).
    """
    import scipy.sparse as sp

    k = _key(prefix, name)
    if value is None:
        tags[name] = "none"
    elif isinstance(value, (bool, np.bool_)):
        tags[name] = "bool"
        arrays[k] = np.asarray(bool(value))
    elif isinstance(value, (int, np.integer)):
        tags[name] = "int"
        arrays[k] = np.asarray(int(value), dtype=np.int64)
    elif isinstance(value, (float, np.floating)):
        tags[name] = "float"
        arrays[k] = np.asarray(float(value), dtype=np.float64)
    elif isinstance(value, str):
        tags[name] = ["str", value]
    elif isinstance(value, np.ndarray):
        _require_plain(value, k)
        tags[name] = "array"
        arrays[k] = value
    elif sp.issparse(value):
        if value.format != "csr":
            raise TypeError(f"{k}: only CSR sparse matrices are encoded, got {value.format}")
        tags[name] = ["csr", "array" if isinstance(value, sp.sparray) else "matrix", list(value.shape)]
        for part in ("data", "indices", "indptr"):
            arrays[f"{k}.{part}"] = getattr(value, part)
    elif isinstance(value, (tuple, list)) and value and all(isinstance(v, np.ndarray) for v in value):
        for v in value:
            _require_plain(v, k)
        tags[name] = ["arrays", type(value).__name__]
        arrays[f"{k}.lengths"] = np.array([v.size for v in value], dtype=np.int64)
        arrays[f"{k}.values"] = np.concatenate([v.ravel() for v in value])
    elif isinstance(value, tuple) and all(isinstance(v, (int, np.integer)) for v in value):
        tags[name] = ["ints", [int(v) for v in value]]
    else:
        raise TypeError(f"{k}: cannot encode a {type(value).__name__} as plain arrays")


def _require_plain(a: np.ndarray, k: str) -> None:
    if a.dtype.kind not in "biufc":
        raise TypeError(f"{k}: arrays of dtype {a.dtype} are not plain numeric data")


def get(prefix: str, name: str, arrays: Mapping[str, np.ndarray], tags: Mapping) -> Any:
    """The value :func:`put` stored under ``prefix.name`` (KeyError/ValueError if absent or damaged)."""
    import scipy.sparse as sp

    k = _key(prefix, name)
    tag = tags[name]
    if tag == "none":
        return None
    if tag in ("bool", "int", "float"):
        a = arrays[k]
        if a.shape != ():
            raise ValueError(f"{k}: expected a number, got an array of shape {a.shape}")
        return {"bool": bool, "int": int, "float": float}[tag](a)
    if tag == "array":
        return np.array(arrays[k])
    kind = tag[0]
    if kind == "str":
        return str(tag[1])
    if kind == "ints":
        return tuple(int(v) for v in tag[1])
    if kind == "csr":
        cls = sp.csr_array if tag[1] == "array" else sp.csr_matrix
        parts = tuple(np.array(arrays[f"{k}.{p}"]) for p in ("data", "indices", "indptr"))
        return cls(parts, shape=tuple(int(n) for n in tag[2]))
    if kind == "arrays":
        lengths, values = arrays[f"{k}.lengths"], arrays[f"{k}.values"]
        if int(lengths.sum()) != values.size or (lengths < 0).any():
            raise ValueError(f"{k}: lengths do not add up to the stored values")
        out = [np.array(v) for v in np.split(values, np.cumsum(lengths)[:-1])]
        return tuple(out) if tag[1] == "tuple" else out
    raise ValueError(f"{k}: unknown tag {tag!r}")


def put_fields(prefix: str, values: Mapping[str, Any], arrays: dict, meta: dict) -> None:
    """Store every ``name: value`` of ``values``; the tags go to ``meta[prefix]``."""
    tags: dict = {}
    for name, v in values.items():
        put(prefix, name, v, arrays, tags)
    meta[prefix] = tags


def get_fields(prefix: str, arrays: Mapping[str, np.ndarray], meta: Mapping) -> dict:
    """The ``name: value`` dict :func:`put_fields` stored under ``prefix``."""
    tags = meta[prefix]
    if not isinstance(tags, dict):
        raise ValueError(f"{prefix}: damaged metadata")
    return {name: get(prefix, name, arrays, tags) for name in tags}


def put_dataclass(prefix: str, obj, arrays: dict, meta: dict) -> None:
    """Store the fields of a dataclass instance (rebuild it with ``cls(**get_fields(...))``)."""
    put_fields(prefix, {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}, arrays, meta)
