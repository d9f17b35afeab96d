r"""A resumable sampled defect correction: every finished solve kept in a JSON-lines file.

The sampled estimate of a large image (:func:`porefsi.stokes.sampled_permeability`) is a long run
of independent solves: the whole image at its own resolution (~25 CPU-min for the 400³ Berea) and
every block at every level (up to ~5 CPU-min each at f = 4). :func:`resume_sampled_permeability`
records each solve in ``path`` the moment it finishes and, run again with the same file, takes the
solves it holds instead of repeating them, so an interrupted run loses at most the solve in
progress and a resumed run gives the same numbers as an uninterrupted one (JSON round-trips floats
exactly).

The file (JSON lines, no pickles):

* line 1, the header: ``{"format": "porefsi-sampled-resume", "version": 1, "image_sha256": ...,
  "shape": [...], "voxel_size_m": ..., "axis": "x", "block": 40, "options": {...}}``; the image
  digest is the SHA-256 of the pore mask, shape and voxel size, and ``options`` the solver options
  that change a result (boundary, buffer, lateral, mirror, wall, viscosity, dp, rtol, maxiter);
* then one record per solve: ``{"kind": "native", "result": {...}}`` (the whole image's
  :class:`~porefsi.stokes.StokesResult` without its fields and residual history) or
  ``{"kind": "block", "origin": [i, j, k], "refine": f, "k_mD": ..., "cpu_s": ..., "iterations": ...}``.

Before anything is reused the header must match the run (image, axis, block side, options), else
:class:`~porefsi.errors.InputError` names the field that differs. A record is reused only at the
level and block origin it was solved for, so the same file serves a later run with more levels
(e.g. 1, 2, 3 first, then 1, 2, 3, 4) or more blocks. Records are appended with one ``write`` of a
whole line to a file opened for appending, then flushed to disk; a line cut short by a kill is
dropped (and truncated away before the next append), a malformed line elsewhere is an error.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.image.voxel_image import AXES, VoxelImage, axis_index
from porefsi.io.results import atomic_write_text
from porefsi.stokes.permeability import StokesOptions, StokesResult
from porefsi.stokes.sampled import (
    DEFAULT_BLOCKS,
    SampledExtrapolation,
    _check_levels,
    _check_side,
    _sampled_options,
    prepare_sampled,
    run_sampled,
)

__all__ = ["ResumeFile", "resume_sampled_permeability", "image_digest", "FORMAT", "VERSION"]

FORMAT = "porefsi-sampled-resume"
VERSION = 1
#: Solver options recorded in the header: the ones that change a solve's result.
RESULT_OPTIONS = ("boundary", "buffer", "lateral", "mirror", "wall", "viscosity", "dp", "rtol", "maxiter")
#: StokesResult fields stored for the native solve (``pressure``/``velocity`` are never stored).
_RESULT_FIELDS = tuple(f.name for f in dataclasses.fields(StokesResult) if f.name not in ("pressure", "velocity"))


def image_digest(image: VoxelImage) -> str:
    """SHA-256 (hex) of the image's pore mask (C order), shape and voxel size: what a solve depends on."""
    h = hashlib.sha256()
    h.update(json.dumps({"shape": list(image.shape), "voxel_size_m": float(image.voxel_size)}).encode())
    h.update(np.packbits(np.ascontiguousarray(image.pore), axis=None).tobytes())
    return h.hexdigest()


def _header(image: VoxelImage, ax: int, side: int, opts: StokesOptions) -> dict:
    return {"format": FORMAT, "version": VERSION, "image_sha256": image_digest(image), "shape": list(image.shape),
            "voxel_size_m": float(image.voxel_size), "axis": AXES[ax], "block": int(side),
            "options": {k: getattr(opts, k) for k in RESULT_OPTIONS}}


def _plain(value):
    """JSON fallback for numpy scalars (and arrays) in a result."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


def _result_record(res: StokesResult) -> dict:
    out = {k: getattr(res, k) for k in _RESULT_FIELDS}
    out["info"] = {k: v for k, v in res.info.items() if k != "history"}
    return out


class ResumeFile:
    """The records of one resumable sampled run (module notes): read, validated, appended to.

    Parameters
    ----------
    path : str or Path
        The JSON-lines file; created (header only, atomically) by :meth:`create` if absent.
    header : dict
        What the run is: a file with another header is refused (:class:`InputError`).
    """

    def __init__(self, path, header: dict):
        self.path, self.header = Path(path), header
        self._native, self._blocks, self._good_size = None, {}, None
        if self.path.is_dir() or not self.path.parent.is_dir():
            raise InputError(f"--resume {self.path}: needs a file in an existing folder; create the folder or "
                             "give another path")
        if self.path.exists():
            self._read()

    def _read(self) -> None:
        data = self.path.read_bytes()
        end = data.rfind(b"\n") + 1  # bytes after the last newline: a record cut short by a kill
        self._good_size = end
        lines = data[:end].decode("utf-8").splitlines()
        if not lines:
            raise InputError(f"--resume {self.path} holds no header (empty or cut short before its first line); "
                             "delete it (the run starts over) or give another path")
        try:
            records = [json.loads(line) for line in lines]
        except json.JSONDecodeError as exc:
            raise InputError(f"--resume {self.path}: line {exc.doc!r:.60} is not JSON; the file is damaged: "
                             "delete it (the run starts over) or give another path") from None
        head = records[0]
        if not isinstance(head, dict) or head.get("format") != FORMAT:
            raise InputError(f"--resume {self.path} is not a porefsi sampled-resume file; give another path")
        for key in ("version", "image_sha256", "shape", "voxel_size_m", "axis", "block", "options"):
            if head.get(key) != self.header[key]:
                raise InputError(f"--resume {self.path} was written for {key} {head.get(key)!r}, this run has "
                                 f"{self.header[key]!r}; use a new file for this run (or the matching run's options)")
        for r in records[1:]:
            if r.get("kind") == "native":
                self._native = StokesResult(**r["result"])
            elif r.get("kind") == "block":
                self._blocks[(tuple(int(v) for v in r["origin"]), int(r["refine"]))] = (float(r["k_mD"]),
                                                                                         float(r["cpu_s"]))

    def create(self) -> None:
        """Write the header (temporary file, then rename) unless the file exists."""
        if self.path.exists():
            return
        atomic_write_text(self.path, json.dumps(self.header) + "\n")
        self._good_size = None

    def native(self) -> StokesResult | None:
        """The whole image's solve at its own resolution, if recorded (no fields, no history)."""
        return self._native

    def block(self, origin, f: int):
        """``(k_mD, cpu_s)`` of the block at ``origin`` refined ``f`` times, if recorded, else None."""
        return self._blocks.get((tuple(int(v) for v in origin), int(f)))

    def put_native(self, res: StokesResult) -> None:
        """Record the whole image's native solve."""
        self._append({"kind": "native", "result": _result_record(res)})
        self._native = res

    def put_block(self, origin, f: int, k_mD: float, cpu_s: float, iterations: int) -> None:  # noqa: N803
        """Record the block at ``origin`` solved refined ``f`` times: k in mD, CPU s, MINRES iterations."""
        o = tuple(int(v) for v in origin)
        self._append({"kind": "block", "origin": list(o), "refine": int(f), "k_mD": float(k_mD),
                      "cpu_s": float(cpu_s), "iterations": int(iterations)})
        self._blocks[(o, int(f))] = (float(k_mD), float(cpu_s))

    def _append(self, record: dict) -> None:
        """One whole line in one ``write`` (after dropping a line cut short earlier), then fsync."""
        line = (json.dumps(record, default=_plain) + "\n").encode("utf-8")
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
        try:
            if self._good_size is not None and os.fstat(fd).st_size > self._good_size:
                os.ftruncate(fd, self._good_size)
            self._good_size = None
            os.write(fd, line)
            os.fsync(fd)
        finally:
            os.close(fd)


def resume_sampled_permeability(image: VoxelImage, path, axis="x", levels=(1, 2, 3), blocks: int = DEFAULT_BLOCKS,
                                block: int | None = None, options: StokesOptions | None = None,
                                **overrides) -> SampledExtrapolation:
    """:func:`porefsi.stokes.sampled_permeability` that keeps every finished solve in ``path``.

    Parameters as :func:`~porefsi.stokes.sampled_permeability` (the native solve is always the
    file's or solved here), plus ``path``: the JSON-lines file of the module notes, created if
    absent (after every parameter is validated), read and checked against this run if present.

    Returns
    -------
    SampledExtrapolation
        The same numbers as an uninterrupted run; ``native`` is the recorded solve (without its
        residual history) when it came from the file, and a block's ``cpu_seconds`` the CPU time
        its solves took when they were made.

    Raises
    ------
    InputError
        Bad parameters (as sampled_permeability), a file written for another image, axis, block
        side or options, or a damaged file.
    """
    t0 = time.perf_counter()
    opts = _sampled_options(image, options, overrides)
    ax = axis_index(axis)
    side = _check_side(image, block, _check_levels(levels)[-1], ax, opts)
    store = ResumeFile(path, _header(image, ax, side, opts))
    plan = prepare_sampled(image, ax, levels, blocks, side, store.native(), opts)
    store.create()
    return run_sampled(image, plan, opts, store, t0)
