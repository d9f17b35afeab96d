"""``porefsi drainage``: time-resolved two-phase drainage on a pore network (DPN).

Writes ``DIR/drainage.csv`` (one row per event, columns
:data:`porefsi.flow.drainage.HISTORY_COLUMNS`; ``capillary_pressure_pa`` is the inlet minus the
outlet node pressure, the outlet being at 0 by construction), ``DIR/invasion.csv``
(``pore,time_s``: when each pore became fully non-wetting, empty if never), per-pore snapshots
``DIR/snapshot_<k>.csv`` (``pore,time_s,pressure_pa,fluid_pressure_pa,nw_saturation,state``) and
``DIR/pc_s.png``: the dynamic Pc–S curve next to the quasi-static one (invasion percolation with
trapping on the same network and fluids). With ``-o DIR`` the run is saved to
``DIR/drainage_checkpoint.npz`` every ``--checkpoint-every`` seconds (a progress line on stderr
each time); ``--resume`` continues a killed run from it, to the same result bit for bit. A
fresh run first removes what an earlier run wrote in DIR (those file names only). A progress line
(simulated time, saturation, inlet pressure, events, full pores, wall seconds) goes to stderr
every ``--progress-every`` seconds: 5 s by default when stderr is not a terminal (logs of batch
jobs), 10 s when it is; the first once the inputs are checked and the run starts, with or without ``-o``.
``--scheme adaptive`` runs the adaptive scheme (docs/drainage.md).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

from porefsi.cli._common import _ArgumentError, emit, positive_float
from porefsi.errors import InputError

__all__ = ["register", "run", "write_pc_s", "CHECKPOINT"]

#: Checkpoint file name inside the output directory.
CHECKPOINT = "drainage_checkpoint.npz"


def register(subparsers) -> None:
    """Add the ``drainage`` subcommand."""
    from porefsi.cli._extract import add_network_args
    from porefsi.flow import DrainageOptions
    from porefsi.flow.drainage import DEFAULT_SCHEME, PAPER_RATE, PAPER_T_END, SCHEMES

    defaults = DrainageOptions()  # the option defaults, shown in --help
    p = subparsers.add_parser(
        "drainage", help="dynamic two-phase drainage (non-wetting injection at constant rate)",
        description="Inject the non-wetting fluid at a constant rate through the low face of --axis and "
        "follow the displacement in time (event-driven dynamic pore-network model). Defaults are the "
        "paper's: 1.25e-13 m^3/s for 20 s, 1 cP wetting / 10 cP non-wetting, contact angle 0; the "
        "interfacial tension default 0.03 N/m is porefsi's choice for oil/brine (the paper gives none).",
    )
    add_network_args(p)
    p.add_argument("--rate", type=positive_float, default=PAPER_RATE, help="injection rate, m^3/s")
    p.add_argument("--t-end", type=positive_float, default=PAPER_T_END, help="injection time, s")
    p.add_argument("--mu-w", type=positive_float, default=1e-3, help="wetting viscosity, Pa.s (default 1 cP)")
    p.add_argument("--mu-n", type=positive_float, default=1e-2, help="non-wetting viscosity, Pa.s (10 cP)")
    p.add_argument("--sigma", type=positive_float, default=0.03, help="interfacial tension, N/m (0.03)")
    p.add_argument("--theta", type=float, default=0.0, help="contact angle through the wetting fluid, "
                   "degrees, in [0, 90) (default 0)")
    p.add_argument("--scheme", choices=SCHEMES, default=DEFAULT_SCHEME,
                   help="exact: a pressure solve after every event (the reference); adaptive: quasi-static fills "
                   "in certified batches without solves, local pressure updates elsewhere (docs/drainage.md; "
                   f"default {DEFAULT_SCHEME})")
    p.add_argument("--tie-tolerance", type=_nonnegative_float, default=None, metavar="TAU",
                   help="adaptive only: relative band by which a quasi-static fill's pressure bound may exceed the "
                   "next threshold and still be filled without a solve (0 = the rigorous certificate; default "
                   f"{defaults.tie_tolerance:g}, applied up to Ca = 1e-6)")
    p.add_argument("--predict-fills", type=_nonnegative_int, default=None, metavar="M",
                   help="adaptive only: with active menisci, most fills made with the last solve's flux split "
                   "before one solve checks them (rolled back if the check fails); 0 = off, the default "
                   "(measured to save nothing, docs/drainage.md)")
    p.add_argument("--flux-tolerance", type=_nonnegative_float, default=None, metavar="EPS",
                   help=f"adaptive only: the --predict-fills check's tolerance on the flux split, sum |dq| / rate "
                   f"(default {defaults.flux_tolerance:g}, at most 2)")
    p.add_argument("--block-pivots", choices=("on", "off"), default=None,
                   help="adaptive only: close every pushed-back meniscus of an event at once, checked by the next "
                   "solve (on, the default) or one per solve as the exact scheme (off)")
    p.add_argument("--backoff", type=_nonnegative_int, default=None, metavar="STEPS",
                   help=f"adaptive only: most steps without a quasi-static batch attempt after attempts that "
                   f"certified nothing (0 = attempt at every step; default {defaults.backoff})")
    p.add_argument("--snapshots", type=int, default=5, metavar="K",
                   help="number of evenly spaced per-pore snapshots written to DIR (default 5)")
    p.add_argument("-o", "--output", default=None, metavar="DIR",
                   help="directory for the CSV outputs and the Pc-S figure pc_s.png")
    p.add_argument("--checkpoint-every", type=positive_float, default=60.0, metavar="SECONDS",
                   help="with -o: save the run to DIR/drainage_checkpoint.npz every SECONDS of wall time "
                   "(default 60) and report progress on stderr")
    p.add_argument("--progress-every", type=positive_float, default=None, metavar="SECONDS",
                   help=f"wall seconds between two progress lines on stderr (default {REPORT_EVERY:g} when "
                   f"stderr is not a terminal, {REPORT_EVERY_TTY:g} when it is)")
    p.add_argument("--resume", action="store_true",
                   help="continue a killed or interrupted run from DIR/drainage_checkpoint.npz (same arguments)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of an earlier drainage run in DIR (refused without it), once the "
                   "inputs have been read and checked")
    p.add_argument("--force", action="store_true", help=f"allow more than {MAX_SNAPSHOTS} --snapshots")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


#: Command-line flags of the adaptive scheme's knobs (the DrainageOptions field of each).
_ADAPTIVE_FLAGS = {"tie_tolerance": "--tie-tolerance", "predict_fills": "--predict-fills",
                   "flux_tolerance": "--flux-tolerance", "backoff": "--backoff", "block_pivots": "--block-pivots"}


def _nonnegative_float(text: str) -> float:
    """Argparse type: a finite float >= 0."""
    try:
        x = float(text)
    except ValueError:
        raise _ArgumentError(f"expected a number, got {text!r}") from None
    if not np.isfinite(x) or x < 0:
        raise _ArgumentError(f"expected a finite number >= 0, got {text!r}")
    return x


def _nonnegative_int(text: str) -> int:
    """Argparse type: an integer >= 0."""
    try:
        k = int(text)
    except ValueError:
        raise _ArgumentError(f"expected an integer, got {text!r}") from None
    if k < 0:
        raise _ArgumentError(f"expected an integer >= 0, got {text!r}")
    return k


def _adaptive_knobs(args: argparse.Namespace) -> dict:
    """The adaptive knobs given on the command line (an error naming the flag if the scheme is exact)."""
    given = {k: getattr(args, k) for k in _ADAPTIVE_FLAGS if getattr(args, k, None) is not None}
    if given and args.scheme != "adaptive":
        flags = ", ".join(_ADAPTIVE_FLAGS[k] for k in given)
        raise InputError(f"{flags} apply to --scheme adaptive only (the scheme is {args.scheme}); "
                         "add --scheme adaptive or drop them")
    if given.get("flux_tolerance", 0.0) > 2.0:
        raise InputError(f"--flux-tolerance must be at most 2 (a sum of flux differences over the rate), "
                         f"got {given['flux_tolerance']:g}")
    return given


def run(args: argparse.Namespace) -> int:
    """Run the drainage described by ``args``; write the outputs; print the summary.

    Every input (options, network or image, the checkpoint of ``--resume`` and its fingerprint)
    is read and checked before anything in ``-o DIR`` changes; the outputs are written
    atomically at the end.
    """
    from porefsi.cli._extract import network_from_args
    from porefsi.flow.drainage import DrainageOptions, DrainageSimulator, RunControl, simulate_drainage
    from porefsi.flow.fluids import Fluids
    from porefsi.io import rundir

    fluids = Fluids(mu_w=args.mu_w, mu_n=args.mu_n, sigma=args.sigma, theta_deg=args.theta)
    if args.snapshots < 0:
        raise InputError(f"--snapshots must be >= 0, got {args.snapshots}")
    if args.snapshots > MAX_SNAPSHOTS and not args.force:
        raise InputError(f"--snapshots {args.snapshots} would write {args.snapshots} files of one row per pore "
                         f"(limit {MAX_SNAPSHOTS}); pass fewer, or --force")
    if args.resume and not args.output:
        raise InputError(f"--resume needs -o DIR: the checkpoint is DIR/{CHECKPOINT}")
    if args.resume and args.overwrite:
        raise InputError("--resume continues the run in DIR and --overwrite replaces it: pass one of them")
    t0 = time.perf_counter()
    out = rundir.check_output_dir(args.output) if args.output else None
    if out is not None and not args.resume:
        _refuse_existing(out, args.overwrite)
    net = network_from_args(args)
    from porefsi.flow.plausible import warn_injection_pressure

    warn_injection_pressure(net, args.axis, args.rate, args.mu_n)
    times = np.linspace(0, args.t_end, args.snapshots + 1)[1:] if args.snapshots else None
    tty = sys.stderr.isatty()
    every = args.progress_every or (REPORT_EVERY_TTY if tty else REPORT_EVERY)
    options = DrainageOptions(rate=args.rate, t_end=args.t_end, scheme=args.scheme,  # argparse checked each
                              **_adaptive_knobs(args))
    report = dict(report=_progress(args.t_end, saved=False), report_every=every)
    if out is None:
        res = simulate_drainage(net, fluids, options, axis=args.axis, times=times, run=RunControl(**report))
        return _report(args, net, res, None, t0)
    if not args.resume:  # fails here (no spanning path, bad options) before the folder is touched
        DrainageSimulator(net, fluids, options, axis=args.axis)
    with rundir.lock(out), rundir.output_errors(out):
        if not args.resume:
            _refuse_existing(out, args.overwrite)  # again: a run may have finished there meanwhile
            _clear_outputs(out)
        # a resumed run reads and checks its checkpoint before it changes anything
        control = RunControl(checkpoint=out / CHECKPOINT, checkpoint_every=args.checkpoint_every,
                             resume=args.resume, progress=_progress(args.t_end), **report)
        res = simulate_drainage(net, fluids, options, axis=args.axis, times=times, run=control)
        _write_outputs(out, net, fluids, args, res)
    return _report(args, net, res, out, t0)


#: Most snapshot files ``--snapshots`` writes without ``--force``.
MAX_SNAPSHOTS = 1000


def _write_outputs(out: Path, net, fluids, args, res) -> None:
    """drainage.csv, invasion.csv, snapshot_<k>.csv (stale extra ones removed), pc_s.png; atomically."""
    import io

    from porefsi.flow.drainage import HISTORY_COLUMNS
    from porefsi.io.results import atomic_path, atomic_write_text

    def table(columns, header, fmt="%.10g") -> str:
        buf = io.StringIO()
        np.savetxt(buf, np.column_stack(columns), delimiter=",", header=header, comments="", fmt=fmt)
        return buf.getvalue()

    h = res.history
    atomic_write_text(out / "drainage.csv", table([h[k] for k in HISTORY_COLUMNS], ",".join(HISTORY_COLUMNS)))
    atomic_write_text(out / "invasion.csv", "pore,time_s\n" + "".join(
        f"{i},{'' if np.isnan(t) else repr(float(t))}\n" for i, t in enumerate(res.invasion_time)))
    for k, s in enumerate(res.snapshots):
        cols = [np.arange(net.n_pores), np.full(net.n_pores, s.t), s.pressure, s.fluid_pressure,
                s.nw_saturation, s.pore_state]
        atomic_write_text(out / f"snapshot_{k}.csv", table(
            cols, "pore,time_s,pressure_pa,fluid_pressure_pa,nw_saturation,state",
            fmt=["%d", "%.10g", "%.10g", "%.10g", "%.10g", "%d"]))
    for f in out.glob("snapshot_*.csv"):  # an earlier run's extra snapshots (this one wrote fewer)
        m = re.fullmatch(r"snapshot_(\d+)\.csv", f.name)
        if m and int(m[1]) >= len(res.snapshots):
            f.unlink()
    with atomic_path(out / "pc_s.png") as tmp:
        write_pc_s(tmp, net, fluids, args.axis, args.rate, res)


def _report(args, net, res, out, t0) -> int:
    from porefsi.flow.plausible import warn_pressure_reached

    p = res.history["inlet_pressure_pa"]
    warn_pressure_reached(float(np.nanmax(p)) if np.isfinite(p).any() else float("nan"))
    c = res.counters
    summary = {
        "n_pores": net.n_pores, "n_dropped_pores": res.n_dropped, "scheme": args.scheme,
        "breakthrough_time_s": res.breakthrough_time, "breakthrough_sw": res.breakthrough_sw,
        "final_sw": res.final.sw, "final_inlet_pressure_pa": res.final.inlet_pressure,
        "n_events": c["n_events"], "n_solves": c["n_solves"], "n_jumps": c["n_jumps"],
        **{k: c[k] for k in ("n_certified_fills", "n_local_solves", "n_global_solves") if k in c},
        "mass_balance_error": res.mass_balance_error, "seconds": time.perf_counter() - t0,
        "output": str(out) if out else None,
    }
    emit(summary, args.json)
    return 0


#: Files this command writes in its output directory (only these are ever removed).
_OUTPUTS = re.compile(r"drainage\.csv|invasion\.csv|pc_s\.png|snapshot_\d+\.csv|drainage_checkpoint\.(npz|pkl)")
#: A temporary file of :func:`porefsi.io.results.atomic_write_bytes` that a killed run left.
_TEMPORARY = re.compile(r"\.(?P<name>.+?)\.[^.]+\.tmp(\.[^.]+)?")


def _refuse_existing(out: Path, overwrite: bool) -> None:
    """Refuse a fresh run into a folder holding a drainage run's results, unless ``overwrite``."""
    if overwrite or not out.is_dir():
        return
    held = [n for n in (CHECKPOINT, "drainage_checkpoint.pkl", "drainage.csv") if (out / n).is_file()]
    if held:
        raise InputError(f"output folder {out} already holds a drainage run ({', '.join(held)}): continue it with "
                         "--resume (same options), pass --overwrite to replace its results, or pass another -o DIR")


def _clear_outputs(out: Path) -> None:
    """Remove the files an earlier run wrote in ``out`` (and temporaries a killed run left).

    Files of other names are never touched.
    """
    for f in out.iterdir():
        tmp = _TEMPORARY.fullmatch(f.name)
        name = tmp["name"] if tmp else f.name
        if f.is_file() and _OUTPUTS.fullmatch(name):
            f.unlink()


#: Wall seconds between two progress lines on stderr when it is not a terminal (logs), and when it is.
REPORT_EVERY = 5.0
REPORT_EVERY_TTY = 10.0


def _progress(t_end: float, saved: bool = True):
    """A callback printing one progress line on stderr (after a checkpoint, or periodically)."""
    def report(sim, seconds):
        st = sim._engine
        p_in = _last_inlet_pressure(st)
        p_txt = f"{p_in:.5g} Pa" if np.isfinite(p_in) else "- (no pressure solve yet)"
        print(f"drainage: t = {st.t:.4g} / {t_end:g} s, Sw = {st.sw():.4f}, P_in = {p_txt}, "
              f"{st.n_events} events, {st.n_fills} pores full, {seconds:.0f} s wall"
              f"{' (checkpoint saved)' if saved else ''}", file=sys.stderr, flush=True)
    return report


def _last_inlet_pressure(engine) -> float:
    """The inlet pressure of the engine's latest event that has one (NaN if none of the last 10000)."""
    rows = engine.rows
    for k in range(len(rows) - 1, max(len(rows) - 10000, 0) - 1, -1):
        if np.isfinite(rows[k][3]):  # column 3: inlet_pressure_pa (drainage._ROW_COLUMNS)
            return float(rows[k][3])
    return float("nan")


def write_pc_s(path, net, fluids, axis, rate: float, res) -> Path:
    """Draw the run's dynamic Pc–S curve next to the quasi-static one (IP with trapping) into ``path``."""
    from porefsi.flow.invasion import invasion_percolation
    from porefsi.plot import plot_drainage_pc_s

    h = res.history
    ip = invasion_percolation(net, fluids, axis=axis)
    return plot_drainage_pc_s((h["sw"], h["capillary_pressure_pa"]), ip.pc_curve(), path,
                              breakthrough_sw=res.breakthrough_sw,
                              title=f"{net.n_pores} pores, Q = {rate:.3g} m^3/s, Ca = "
                                    f"{fluids.capillary_number(rate, _face_area(net, axis)):.2g}")


def _face_area(net, axis) -> float:
    from porefsi.image.voxel_image import axis_index

    return float(np.prod(np.delete(np.asarray(net.extent, float), axis_index(axis))))
