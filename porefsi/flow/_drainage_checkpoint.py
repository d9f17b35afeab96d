"""Checkpoints of a drainage run (private; used by :func:`porefsi.flow.drainage.simulate_drainage`).

A checkpoint is one ``.npz`` of plain numeric arrays plus a JSON metadata record
(:func:`porefsi.io.results.save_checkpoint`, written atomically), loaded with
``allow_pickle=False``: a checkpoint from someone else cannot run code. It holds the simulator
between two events (network, fluids, options, every engine array and counter, the pressure
solver's counters and its low-rank base as a recipe: the base matrix's values and the batches
of cached columns, rebuilt identically on resume), the snapshots taken so far and the run's
elapsed seconds, stamped with a fingerprint of everything that determines the run (network
arrays, fluids, boundary condition, axis, end and snapshot times, solver options) and a format
version. A resumed run refuses a checkpoint of a different run, and a damaged one with a
one-line :class:`~porefsi.errors.InputError` naming the file and the fix.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from porefsi.errors import InputError, PorefsiError
from porefsi.flow._drainage_options import PREDICTOR_KNOBS, DrainageOptions
from porefsi.flow._drainage_simulator import ROW_COLUMNS, DrainageSimulator
from porefsi.flow.fluids import Fluids
from porefsi.flow.state import FlowState
from porefsi.io import interrupt, plain
from porefsi.io.results import load_checkpoint, save_checkpoint
from porefsi.network.network import Network

__all__ = ["fingerprint", "save", "load", "deferred_interrupt", "FORMAT", "simulator_state",
           "simulator_from_state"]

#: Layout version of the checkpoint (1: a pickle, no longer read; 2: plain arrays + JSON).
FORMAT = 2
#: What :func:`load` tells a user to do with a checkpoint it cannot use.
_FIX = "run again without --resume to start over (with --overwrite on the command line)"

#: Engine attributes rebuilt by ``Engine(graph, rate, inlet_pressure, **options)`` (not stored).
_ENGINE_DERIVED = frozenset({"g", "solver", "rate", "p_fixed", "skip_solves", "max_iter", "_nbr_res", "_diag_ref",
                             "_ptol", "_indptr"})
#: Solver attributes that are factorisations (rebuilt) or the base (stored as its recipe).
_SOLVER_DERIVED = frozenset({"_ml", "_ml_iters", "_base", "_saved_base", "_dpos", "_dpos_for", "_sel", "_sel_saved"})
#: Every attribute of a DrainageSimulator this module knows how to store.
_SIM_ATTRS = frozenset({"net", "fluids", "axis", "rate", "inlet_pressure_bc", "graph", "_opts", "_engine",
                        "last_remap", "options"})
_ROW_WIDTH = len(ROW_COLUMNS)  # columns of the engine's per-event rows


def fingerprint(net, fluids, settings: dict) -> str:
    """SHA-1 (hex) of the network's arrays, the fluids and the run ``settings``."""
    h = hashlib.sha1()
    for f in dataclasses.fields(net):
        v = getattr(net, f.name)
        h.update(f.name.encode())
        if isinstance(v, np.ndarray):
            h.update(str((v.dtype, v.shape)).encode())
            h.update(memoryview(np.ascontiguousarray(v)).cast("B"))
        else:
            h.update(repr(v).encode())
    h.update(repr(dataclasses.astuple(fluids)).encode())
    h.update(repr(sorted(settings.items())).encode())
    return h.hexdigest()


def _graph_digest(graph) -> str:
    """SHA-1 of a drainage graph's arrays: a restored simulator must rebuild the very same graph."""
    h = hashlib.sha1()
    for f in dataclasses.fields(graph):
        v = getattr(graph, f.name)
        if isinstance(v, np.ndarray):
            h.update(f.name.encode() + str((v.dtype, v.shape)).encode())
            h.update(memoryview(np.ascontiguousarray(v)).cast("B"))
    return h.hexdigest()


def simulator_state(sim, prefix: str, arrays: dict, meta: dict) -> None:
    """Store a :class:`~porefsi.flow.drainage.DrainageSimulator` as plain arrays under ``prefix``.

    Raises
    ------
    TypeError
        The simulator, its engine or solver hold an attribute this module cannot store (a
        programming error: teach :mod:`porefsi.io.plain` or this function the new attribute).
    """
    extra = set(vars(sim)) - _SIM_ATTRS
    if extra:
        raise TypeError(f"DrainageSimulator attributes {sorted(extra)} are not stored in checkpoints")
    e = sim._engine
    s = e.solver
    plain.put_dataclass(f"{prefix}.net", sim.net, arrays, meta)
    plain.put_dataclass(f"{prefix}.fluids", sim.fluids, arrays, meta)
    plain.put_dataclass(f"{prefix}.options", sim.options, arrays, meta)
    plain.put_fields(f"{prefix}.sim", {"axis": int(sim.axis), "rate": sim.rate, "inlet_pressure": sim.inlet_pressure_bc,
                                       "keep": sim.graph.keep, **{f"opt_{k}": v for k, v in sim._opts.items()}},
                     arrays, meta)
    meta[f"{prefix}.graph_sha1"] = _graph_digest(sim.graph)
    if hasattr(sim, "last_remap"):
        plain.put_fields(f"{prefix}.last_remap", sim.last_remap, arrays, meta)
    engine = {k: v for k, v in vars(e).items() if k not in _ENGINE_DERIVED}
    engine["rows"] = np.asarray(e.rows, dtype=np.float64).reshape(-1, _ROW_WIDTH)
    plain.put_fields(f"{prefix}.engine", engine, arrays, meta)
    plain.put_fields(f"{prefix}.solver", {k: v for k, v in vars(s).items() if k not in _SOLVER_DERIVED},
                     arrays, meta)
    base = s._base if s._base is not None else s._saved_base
    if base is not None:  # the low-rank base as its recipe: values, column batches, prefetch marks
        batches = base["batches"]
        plain.put_fields(f"{prefix}.base", {
            "data": base["data"], "pref": base["pref"], "n_pref": base["n_pref"],
            "batch_sizes": np.array([b.size for b in batches], dtype=np.int64),
            "batch_nodes": np.concatenate(batches) if batches else np.zeros(0, dtype=np.int64)}, arrays, meta)
    sel = (s._sel.data, s._sel.batches) if getattr(s, "_sel", None) is not None else getattr(s, "_sel_saved", None)
    if sel is not None:  # solver 'selinv': the base's values and its node batches
        plain.put_fields(f"{prefix}.selinv", {
            "data": sel[0], "batch_sizes": np.array([b.size for b in sel[1]], dtype=np.int64),
            "batch_nodes": np.concatenate(sel[1]) if sel[1] else np.zeros(0, dtype=np.int64)}, arrays, meta)


def simulator_from_state(prefix: str, arrays: dict, meta: dict):
    """The simulator :func:`simulator_state` stored under ``prefix``, in the same state exactly.

    Raises
    ------
    KeyError, ValueError, TypeError
        Missing or inconsistent entries (the caller turns them into a one-line error).
    """
    net = Network(**plain.get_fields(f"{prefix}.net", arrays, meta))
    fluids = Fluids(**plain.get_fields(f"{prefix}.fluids", arrays, meta))
    d = plain.get_fields(f"{prefix}.sim", arrays, meta)
    opts = {k[4:]: v for k, v in d.items() if k.startswith("opt_")}
    if f"{prefix}.options" in meta:
        fields = plain.get_fields(f"{prefix}.options", arrays, meta)
        if fields.get("scheme") == "adaptive":  # written before the predictor: it ran without
            fields = {**PREDICTOR_KNOBS, **fields}
            opts = {**PREDICTOR_KNOBS, **opts}
        sim = DrainageSimulator(net, fluids, DrainageOptions(**fields), axis=d["axis"], _keep=d["keep"])
        if sim._opts != opts:
            raise ValueError(f"stored engine options {opts} differ from the stored drainage options' {sim._opts}")
    else:  # written before the options object: the engine options and the boundary condition
        bc = {"rate": d["rate"]} if d["inlet_pressure"] is None else {"inlet_pressure": d["inlet_pressure"]}
        if opts.get("scheme") == "adaptive":
            opts.setdefault("tie_tolerance", 0.0)  # adaptive runs before the tolerance: the rigorous certificate
            opts = {**PREDICTOR_KNOBS, **opts}
        sim = DrainageSimulator(net, fluids, axis=d["axis"], _keep=d["keep"], **bc, **opts)
    if _graph_digest(sim.graph) != meta[f"{prefix}.graph_sha1"]:
        raise ValueError("the drainage graph rebuilt from the checkpoint differs from the saved one")
    if f"{prefix}.last_remap" in meta:
        sim.last_remap = plain.get_fields(f"{prefix}.last_remap", arrays, meta)
    e = sim._engine
    engine = plain.get_fields(f"{prefix}.engine", arrays, meta)
    rows = engine.pop("rows")
    if rows.ndim != 2 or rows.shape[1] != _ROW_WIDTH:
        raise ValueError(f"engine rows have shape {rows.shape}")
    for k, v in engine.items():
        _same_kind(getattr(e, k, None), v, f"engine.{k}")
        setattr(e, k, v)
    e.rows = [tuple(r) for r in rows.tolist()]
    s = e.solver
    fields = plain.get_fields(f"{prefix}.solver", arrays, meta)
    for k, v in fields.items():
        setattr(s, k, v)
    if "prefetch_fill" not in fields:  # written before the fill rule: prefetch and rank cap as they were
        s.prefetch_fill = -1.0
    s._base = None
    if f"{prefix}.base" in meta:
        b = plain.get_fields(f"{prefix}.base", arrays, meta)
        sizes, nodes = b["batch_sizes"], b["batch_nodes"]
        if int(sizes.sum()) != nodes.size:
            raise ValueError("solver base batches do not add up")
        s._saved_base = {"data": b["data"], "pref": b["pref"], "n_pref": b["n_pref"],
                         "batches": [np.array(x) for x in np.split(nodes, np.cumsum(sizes)[:-1])] if sizes.size else []}
    s._sel = s._sel_saved = None
    if f"{prefix}.selinv" in meta:
        b = plain.get_fields(f"{prefix}.selinv", arrays, meta)
        sizes, nodes = b["batch_sizes"], b["batch_nodes"]
        if int(sizes.sum()) != nodes.size:
            raise ValueError("solver selinv batches do not add up")
        s._sel_saved = (b["data"], [np.array(x) for x in np.split(nodes, np.cumsum(sizes)[:-1])] if sizes.size else [])
    return sim


def _same_kind(old, new, name: str) -> None:
    """A restored engine array must have the shape of the one the fresh engine made."""
    if isinstance(old, np.ndarray) and (not isinstance(new, np.ndarray) or new.shape != old.shape):
        raise ValueError(f"{name}: shape {getattr(new, 'shape', None)} instead of {old.shape}")


def save(path: str | Path, key: str, payload: dict) -> Path:
    """Write ``payload`` (``sim``, ``snaps``, ``k``, ``seconds``) with its fingerprint ``key`` to ``path``."""
    arrays: dict = {}
    meta: dict = {"format": FORMAT, "kind": "porefsi drainage checkpoint", "key": key, "k": int(payload["k"]),
                  "seconds": float(payload["seconds"]), "n_snaps": len(payload["snaps"])}
    simulator_state(payload["sim"], "sim", arrays, meta)
    for i, snap in enumerate(payload["snaps"]):
        plain.put_dataclass(f"snap{i}", snap, arrays, meta)
    return save_checkpoint(path, arrays, meta)


def load(path: str | Path, key: str) -> dict:
    """Read a checkpoint written by :func:`save` for the run with fingerprint ``key``.

    Raises
    ------
    InputError
        No checkpoint at ``path``, an unreadable, damaged or old-format one, or one of a
        different run; the message names the file and the fix.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"cannot resume: no drainage checkpoint at {path}; run without --resume first "
                         "(a checkpoint is written there while the run goes on)")
    arrays, meta = load_checkpoint(path, "drainage checkpoint", _FIX)
    if meta.get("kind") != "porefsi drainage checkpoint" or meta.get("format") != FORMAT:
        raise InputError(f"cannot resume: {path} is not a drainage checkpoint of this porefsi version "
                         f"(format {meta.get('format')!r}, this version writes {FORMAT}); {_FIX}")
    if meta.get("key") != key and "sim.options" not in meta:
        raise InputError(f"cannot resume: {path} was written by a porefsi version before the drainage options "
                         "object (2026-12-02), whose run fingerprint this version cannot match to the command; "
                         f"{_FIX}")
    if meta.get("key") != key:
        raise InputError(f"cannot resume: the checkpoint {path} belongs to a different run (network, fluids, "
                         "rate, axis, times or solver options differ); repeat the original command with "
                         "--resume, or run without --resume to start over")
    try:
        sim = simulator_from_state("sim", arrays, meta)
        snaps = [FlowState(**plain.get_fields(f"snap{i}", arrays, meta)) for i in range(int(meta["n_snaps"]))]
        k, seconds = int(meta["k"]), float(meta["seconds"])
    except (KeyError, ValueError, TypeError, IndexError, PorefsiError) as exc:
        raise InputError(f"cannot resume: {path} is damaged ({type(exc).__name__}: {exc}); {_FIX}") from None
    return {"sim": sim, "snaps": snaps, "k": k, "seconds": seconds}


def deferred_interrupt(enabled: bool = True):
    """Defer the first Ctrl-C (SIGINT) or SIGTERM to the caller's next safe point; yield a "was it sent" test.

    The caller polls the yielded function between events, saves a checkpoint when it returns a
    true value (the signal number) and raises :class:`KeyboardInterrupt` itself, so an
    interrupted run loses no finished event. The first signal restores the previous handler: a
    second one interrupts at once (an event that takes long, e.g. a factorisation). Outside the
    main thread, or with ``enabled`` False, nothing is installed and the test is always false.
    See :func:`porefsi.io.interrupt.deferred`.
    """
    return interrupt.deferred(enabled)
