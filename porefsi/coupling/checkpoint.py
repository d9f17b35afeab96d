"""A coupled run's state as plain arrays + JSON metadata, and back.

No pickles: a checkpoint from someone else cannot run code.

Layout version :data:`CHECKPOINT_FORMAT` (1: pickled objects, no longer read; 2: plain arrays).
The arrays hold the solid's free dofs ``u``, ``v``, the voxel ``labels``, the drainage simulator
(``sim.*``, :func:`porefsi.flow._drainage_checkpoint.simulator_state`), the network when it is
not the simulator's (``network.*``), the interface (``interface.*``: its fields and ``method``)
and where the solid stepper's reused factorisation was built (``static_lu_*`` / ``tdg_tangent_*``),
so a resumed run repeats the uninterrupted one bit for bit.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.coupling.hull import HullInterface
from porefsi.coupling.interface import Interface
from porefsi.coupling.traction import TractionInterface
from porefsi.flow import simulator_from_state, simulator_state
from porefsi.io import plain
from porefsi.network.network import Network

__all__ = ["CHECKPOINT_FORMAT", "run_state", "restore_run_state", "interface_state", "interface_from_state"]

#: Layout version of :func:`run_state` (1: pickled objects, no longer read; 2: plain arrays).
CHECKPOINT_FORMAT = 2
#: The interface classes by their ``method`` (the tag stored with the fields).
_INTERFACES = {cls.method: cls for cls in (HullInterface, TractionInterface)}


def interface_state(prefix: str, itf: Interface, arrays: dict, meta: dict) -> None:
    """Store an interface under ``prefix`` (its dataclass fields and its ``method``)."""
    plain.put_fields(prefix, {"method": itf.method, **{f.name: getattr(itf, f.name) for f in dataclasses.fields(itf)}},
                     arrays, meta)


def interface_from_state(prefix: str, arrays: dict, meta: dict) -> Interface:
    """The interface :func:`interface_state` stored.

    Also reads the format-2 checkpoints of earlier porefsi versions (one class, a superset of fields).
    """
    fields = plain.get_fields(prefix, arrays, meta)
    cls = _INTERFACES[fields.pop("method")]
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in fields.items() if k in names})


def run_state(run) -> tuple[dict, dict]:
    """(arrays, metadata) of a :class:`~porefsi.coupling.loop.CoupledRun`."""
    arrays = {"u": run.u, "v": run.v, "labels": run.labels}
    meta = {"format": CHECKPOINT_FORMAT, "step_index": run.step_index, "t": run.t, "seconds": run.seconds,
            "cpu_seconds": run.cpu_seconds, "n_extractions": run.n_extractions,
            "n_extractions_reused": run.n_extractions_reused, "update_seconds": run.update_seconds,
            "update_cpu_seconds": run.update_cpu_seconds, "coarse_load": run.coarse_load}
    simulator_state(run.sim, "sim", arrays, meta)
    meta["network_is_sim_network"] = run.network is run.sim.net
    if not meta["network_is_sim_network"]:
        plain.put_dataclass("network", run.network, arrays, meta)
    interface_state("interface", run.interface, arrays, meta)
    solid_arrays, solid_meta = run.solid.state()
    arrays.update(solid_arrays)
    meta.update(solid_meta)
    return arrays, meta


def restore_run_state(run, arrays: dict, meta: dict) -> None:
    """Put the state :func:`run_state` stored into a fresh run of the same problem.

    Raises
    ------
    ValueError
        Another format version, or displacements of another solid model.
    KeyError, TypeError
        Missing or damaged entries.
    """
    if meta.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"checkpoint format {meta.get('format')!r}, this porefsi reads {CHECKPOINT_FORMAT}")
    run.u = np.array(arrays["u"], dtype=float)
    run.v = np.array(arrays["v"], dtype=float)
    if run.u.shape != (run.model.n_dofs,) or run.v.shape != run.u.shape:
        raise ValueError(f"displacements of {run.u.size} dofs, the solid model has {run.model.n_dofs}")
    run.sim = simulator_from_state("sim", arrays, meta)
    network = run.sim.net if meta["network_is_sim_network"] else Network(**plain.get_fields("network", arrays, meta))
    run.current = dataclasses.replace(run.current, network=network, labels=np.array(arrays["labels"]),
                                      interface=interface_from_state("interface", arrays, meta))
    run.step_index = int(meta["step_index"])
    run.t = float(meta["t"])
    run.seconds = dict(meta["seconds"])
    run.cpu_seconds.update(meta.get("cpu_seconds", {}))
    run.extractions.n_computed = int(meta.get("n_extractions", 0))
    run.extractions.n_reused = int(meta.get("n_extractions_reused", 0))
    run.coarse_load = meta.get("coarse_load")
    run.update_seconds.update(meta.get("update_seconds", {}))
    run.update_cpu_seconds.update(meta.get("update_cpu_seconds", {}))
    run.solid.restore(arrays, meta)
