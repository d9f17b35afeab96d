"""Result files a user opens: CSV time series, JSON summary, ParaView ``.pvd`` series, checkpoints.

Every write is atomic (written to a temporary file in the same directory, then renamed), so a run
killed at any moment leaves either the previous complete file or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from porefsi.errors import InputError

__all__ = ["jsonable", "file_mode", "atomic_write_bytes", "atomic_path", "atomic_write_text", "write_json", "write_csv",
           "write_npz", "PvdSeries",
           "save_checkpoint", "load_checkpoint", "read_pore_steps"]


def file_mode() -> int:
    """Permission bits of a new file under the process's umask (``0o666 & ~umask``), e.g. 0o644."""
    return 0o666 & ~_umask()


def _umask() -> int:
    """The process's umask, read without changing it where Linux allows (``/proc/self/status``)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    old = os.umask(0o022)  # elsewhere: set and restore (not thread-safe, but only the fallback)
    os.umask(old)
    return old


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + ``os.replace``).

    The file gets the permissions a plain ``open(path, "w")`` would give it (``0o666`` less the
    umask), not the ``0o600`` of the temporary file it starts as.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, file_mode())
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None:  # e.g. ENOSPC from write(): name the file
            raise OSError(exc.errno, exc.strerror, str(p)) from exc
        raise
    return p


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path next to ``path`` for a writer that wants a file name (e.g. meshio).

    When the block ends normally the temporary file gets the umask's permissions and is renamed
    over ``path``; when it raises, the temporary file is removed and ``path`` is left as it was.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    # the file's own suffix last, for writers that infer the format from it (matplotlib)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=f".tmp{p.suffix}")
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, file_mode())
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def jsonable(v):
    """``v`` with numpy values as Python ones and NaN/inf as None (JSON-safe), recursively.

    The one JSON converter of porefsi (results, summaries, the command line's ``--json``, the case
    scripts): mappings become dicts with string keys, sequences and sets lists, arrays nested lists,
    paths strings.
    """
    if isinstance(v, Mapping):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, set, frozenset)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, Path):
        return str(v)
    return v


def write_json(path: str | Path, data: Mapping) -> Path:
    """Write ``data`` as indented JSON (NaN/inf become null; numpy values become Python)."""
    return atomic_write_text(path, json.dumps(jsonable(data), indent=2) + "\n")


def write_csv(path: str | Path, columns: Mapping[str, Sequence]) -> Path:
    """Write equal-length columns as a CSV file with a header row (NaN as empty cells)."""
    names = list(columns)
    n = {len(columns[k]) for k in names}
    if len(n) > 1:
        raise ValueError(f"columns have different lengths {sorted(n)}")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    for row in zip(*(columns[k] for k in names), strict=True):
        w.writerow(["" if (isinstance(x, float) and not math.isfinite(x)) else _fmt(x) for x in row])
    return atomic_write_text(path, buf.getvalue())


def write_npz(path: str | Path, arrays: Mapping[str, np.ndarray]) -> Path:
    """Write arrays into one ``.npz`` atomically (no pickles: plain numeric arrays)."""
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return atomic_write_bytes(path, buf.getvalue())


def read_pore_steps(directory: str | Path) -> list[dict[str, np.ndarray]]:
    """The per-exchange-step pore files of a run directory (``pores/step_NNNN.npz``), in step order.

    Each entry holds ``step``, ``time_s``, ``pore_pressure_Pa``, ``nw_saturation``,
    ``pore_radius_m``, ``pore_volume_m3`` and ``pore_coords_m`` of that step's network (the pore
    count can change between steps under re-extraction).

    Examples
    --------
    Pore pressure of pore 0 over time (a run directory ``out``)::

        steps = read_pore_steps(out)
        t = [s["time_s"] for s in steps]
        p0 = [s["pore_pressure_Pa"][0] for s in steps]
    """
    files = sorted(Path(directory, "pores").glob("step_[0-9][0-9][0-9][0-9]*.npz"))
    out = []
    for f in files:
        with np.load(f, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
        d["step"], d["time_s"] = int(d["step"]), float(d["time_s"])
        out.append(d)
    return sorted(out, key=lambda d: d["step"])


def _fmt(x):
    if isinstance(x, (float, np.floating)):
        return repr(float(x))
    if isinstance(x, np.generic):
        return x.item()
    return x


class PvdSeries:
    """A ParaView collection (``.pvd``) of time steps, rewritten atomically on every ``add``.

    Parameters
    ----------
    path : str or Path
        The ``.pvd`` file; the data files it lists are given relative to its folder.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._entries: list[tuple[float, str]] = []

    def add(self, t: float, file: str | Path) -> None:
        """Append the data file ``file`` at time ``t`` (s) and rewrite the collection."""
        rel = os.path.relpath(Path(file), self.path.parent)
        self._entries.append((float(t), rel))
        self.write()

    def truncate(self, t_max: float) -> None:
        """Drop entries later than ``t_max`` (used when a run resumes from a checkpoint)."""
        self._entries = [e for e in self._entries if e[0] <= t_max]
        self.write()

    def write(self) -> None:
        """Write the collection file."""
        rows = "\n".join(f'    <DataSet timestep="{t!r}" group="" part="0" file="{f}"/>' for t, f in self._entries)
        text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                f"  <Collection>\n{rows}\n  </Collection>\n</VTKFile>\n")
        atomic_write_text(self.path, text)

    @classmethod
    def read(cls, path: str | Path) -> PvdSeries:
        """Load an existing collection (to continue it)."""
        s = cls(path)
        if s.path.is_file():
            import xml.etree.ElementTree as ET

            for ds in ET.parse(s.path).getroot().iter("DataSet"):
                s._entries.append((float(ds.get("timestep")), ds.get("file")))
        return s

    @property
    def entries(self) -> list[tuple[float, str]]:
        """(time, relative file) pairs in order."""
        return list(self._entries)


def save_checkpoint(path: str | Path, arrays: Mapping[str, np.ndarray], meta: Mapping) -> Path:
    """Write arrays and JSON metadata into one ``.npz`` atomically."""
    buf = io.BytesIO()
    payload = {k: np.asarray(v) for k, v in arrays.items()}
    payload["__meta__"] = np.frombuffer(json.dumps(jsonable(meta)).encode("utf-8"), dtype=np.uint8)
    np.savez(buf, **payload)
    return atomic_write_bytes(path, buf.getvalue())


def load_checkpoint(path: str | Path, what: str = "checkpoint",
                    fix: str = "run again without --resume to start over") -> tuple[dict[str, np.ndarray], dict]:
    """Read a checkpoint written by :func:`save_checkpoint`: (arrays, metadata).

    Loaded with ``allow_pickle=False``: a file someone else made cannot run code here.

    Raises
    ------
    InputError
        The file is missing, empty, truncated, corrupt or not a checkpoint; the message names
        the file, what is wrong with it and ``fix``.
    """
    p = Path(path)

    def bad(cause: str) -> InputError:
        return InputError(f"{p} is not a usable {what}: {cause}; {fix}")

    try:
        size = p.stat().st_size
    except OSError as exc:
        raise bad(f"cannot read it ({exc.strerror or exc})") from None
    if size == 0:
        raise bad("the file is empty (a disk that filled up, or a copy that did not finish?)")
    with open(p, "rb") as fh:
        head = fh.read(4)
    if head[:1] == b"\x80":
        raise bad("it is a Python pickle (an older porefsi's format, no longer loaded because "
                  "a pickle can run code)")
    if head != b"PK\x03\x04":
        raise bad("it is not a numpy .npz archive (wrong first bytes: truncated, overwritten or another file)")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k != "__meta__"}
            meta = json.loads(bytes(z["__meta__"]).decode("utf-8"))
    except KeyError:
        raise bad("it has no metadata record (not written by porefsi)") from None
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error, UnicodeDecodeError) as exc:
        raise bad(f"it is truncated or corrupt ({type(exc).__name__}: {_no_pickle_advice(exc)})") from None
    if not isinstance(meta, dict):
        raise bad("its metadata record is not a table")
    return arrays, meta


def _no_pickle_advice(exc: BaseException) -> str:
    """The text of numpy's error without its advice to pass allow_pickle (never right for a user's file)."""
    text = str(exc)
    return "not plain numeric arrays" if "allow_pickle" in text else text
