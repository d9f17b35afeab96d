"""Files porefsi writes and reads back.

Atomic writes, results (JSON, CSV, npz, ParaView series), checkpoints as plain arrays, run-directory
locks, ParaView exports of networks and meshes.
"""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "jsonable": "porefsi.io.results",
    "write_json": "porefsi.io.results",
    "write_csv": "porefsi.io.results",
    "write_npz": "porefsi.io.results",
    "atomic_write_text": "porefsi.io.results",
    "atomic_write_bytes": "porefsi.io.results",
    "PvdSeries": "porefsi.io.results",
    "save_checkpoint": "porefsi.io.results",
    "load_checkpoint": "porefsi.io.results",
    "read_pore_steps": "porefsi.io.results",
    "write_network_vtp": "porefsi.io.network_vtk",
    "write_solid_vtu": "porefsi.io.solid_vtk",
    "read_solid_vtu": "porefsi.io.solid_vtk",
    "RunLockedError": "porefsi.io.rundir",
    "check_output_dir": "porefsi.io.rundir",
    "lock": "porefsi.io.rundir",
}

__all__ = [
    "jsonable",
    "write_json",
    "write_csv",
    "write_npz",
    "atomic_write_text",
    "atomic_write_bytes",
    "PvdSeries",
    "save_checkpoint",
    "load_checkpoint",
    "read_pore_steps",
    "write_network_vtp",
    "write_solid_vtu",
    "read_solid_vtu",
    "RunLockedError",
    "check_output_dir",
    "lock",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)
