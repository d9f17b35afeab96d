"""Run every case in ``cases/`` (or the named ones), full or in smoke mode.

A case is a folder with a ``case.toml``. A case with a ``run.py`` runs as
``python run.py [--smoke] [--out DIR]``; one without runs as
``porefsi run case.toml [--smoke] -o DIR``. Each case runs in its own process, with BLAS pinned
to one thread (as on CI) and the repository on ``PYTHONPATH``, so a clean checkout needs no install.

Full runs of cases with a ``run.py`` write their figures and ``results.json`` into the case
folder (the committed figures of the docs); smoke runs and ``porefsi run`` outputs go to
``--out-root`` (default: a temporary folder), so a smoke run never touches committed files.

Usage::

    python cases/run_cases.py [--smoke] [--out-root DIR] [NAME ...]

Exit status 0 when every case ran, 1 when any failed, 2 for an unknown case name.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CASES = Path(__file__).resolve().parent
ROOT = CASES.parent


def discover() -> list[str]:
    """Names of the case folders (those holding a ``case.toml``), sorted."""
    return sorted(p.parent.name for p in CASES.glob("*/case.toml"))


def command(name: str, smoke: bool, out: Path | None) -> list[str]:
    """The command line that runs case ``name``."""
    folder = CASES / name
    if (folder / "run.py").is_file():
        cmd = [sys.executable, str(folder / "run.py")]
        if smoke:
            cmd.append("--smoke")
        if out is not None:
            cmd += ["--out", str(out)]
        return cmd
    cmd = [sys.executable, "-m", "porefsi", "run", str(folder / "case.toml"), "-o", str(out)]
    if smoke:
        cmd.append("--smoke")
    return cmd


def environment() -> dict:
    """The child environment: repository importable, one BLAS thread, headless plotting."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    for key, val in (("OPENBLAS_NUM_THREADS", "1"), ("OMP_NUM_THREADS", "1"), ("MKL_NUM_THREADS", "1"),
                     ("MPLBACKEND", "Agg"), ("PYVISTA_OFF_SCREEN", "true")):
        env.setdefault(key, val)
    return env


def main(argv: list[str] | None = None) -> int:
    """Run the cases; print one line per case and a summary; return the exit status."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*", help="case folder names (default: all)")
    p.add_argument("--smoke", action="store_true", help="seconds-long version of every case")
    p.add_argument("--out-root", type=Path, default=None,
                   help="put each case's outputs in OUT_ROOT/<name> (default: smoke and plain `porefsi run` "
                        "cases in a temporary folder; full run.py cases in their own folder)")
    args = p.parse_args(argv)
    known = discover()
    unknown = [n for n in args.names if n not in known]
    if unknown:
        print(f"unknown case(s) {', '.join(unknown)}; known cases: {', '.join(known)}", file=sys.stderr)
        return 2
    names = args.names or known
    tmp = None
    root = args.out_root
    if root is None:
        tmp = tempfile.TemporaryDirectory(prefix="porefsi-cases-")
        scratch = Path(tmp.name)
    env = environment()
    failed = []
    t_all = time.perf_counter()
    for name in names:
        has_script = (CASES / name / "run.py").is_file()
        if root is not None:
            out = root / name
        elif args.smoke or not has_script:
            out = scratch / name
        else:
            out = None
        print(f"== {name} ({'smoke' if args.smoke else 'full'})", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call(command(name, args.smoke, out), cwd=str(ROOT), env=env)
        dt = time.perf_counter() - t0
        print(f"== {name}: {'ok' if rc == 0 else f'FAILED (exit {rc})'} in {dt:.1f} s", flush=True)
        if rc != 0:
            failed.append(name)
    print(f"{len(names) - len(failed)}/{len(names)} cases ran in {time.perf_counter() - t_all:.1f} s"
          + (f"; failed: {', '.join(failed)}" if failed else ""))
    if tmp is not None:
        tmp.cleanup()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
