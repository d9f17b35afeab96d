"""The results of a sweep: ``sweep.csv`` (one row per member) and the figure of outputs vs varied keys."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from porefsi.io import results

__all__ = ["MEMBER_COLUMNS", "table_columns", "write_table", "plot_sweep"]

#: The columns every ``sweep.csv`` starts with (then the varied keys, then every summary field).
MEMBER_COLUMNS = ("member", "index", "label")
_STATE_COLUMNS = ("status", "error", "attempts", "resumed_from_step", "worker")
#: Summary fields left out of the table: the member's ``status``/``error`` are the row's own
#: (a member that never started has no summary), and ``figures`` is a list of file names.
_SKIP = ("status", "error", "figures")


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        elif not isinstance(v, (list, tuple)):
            out[key] = v
    return out


def table_columns(sweep, records: Sequence[dict | None]) -> dict:
    """Columns (name -> one value per member, in member order) of ``sweep.csv``.

    ``records[i]`` is member i's record from :func:`porefsi.sweep.member.run_member`, or None
    while it has not finished (status ``pending``). Missing values are empty cells.
    """
    rows = []
    summary_keys: dict = {}
    for m, rec in zip(sweep.members, records, strict=True):
        row = {"member": m.name, "index": m.index, "label": m.label or ""}
        row.update({k: _cell(v) for k, v in m.values.items()})
        if rec is None:
            row["status"] = "pending"
        else:
            row.update({k: _cell(rec.get(k)) for k in _STATE_COLUMNS})
            flat = _flatten({k: v for k, v in (rec.get("summary") or {}).items() if k not in _SKIP})
            summary_keys.update(dict.fromkeys(flat))
            row.update(flat)
        rows.append(row)
    names = [*MEMBER_COLUMNS, *sweep.keys, *_STATE_COLUMNS, *(k for k in summary_keys if k not in sweep.keys)]
    return {n: [_cell(r.get(n)) for r in rows] for n in names}


def _cell(v):
    if v is None:
        return ""
    if isinstance(v, float) and not math.isfinite(v):
        return ""
    return v


def write_table(path: str | Path, sweep, records: Sequence[dict | None]) -> Path:
    """Write ``sweep.csv`` atomically (readers never see half a file)."""
    return results.write_csv(path, table_columns(sweep, records))


def _number(v) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v) if math.isfinite(v) else None


def plot_sweep(path: str | Path, sweep, records: Sequence[dict | None]) -> Path | None:
    """Figure of the ``[plot]`` outputs against its varied key, one line per setting of the others.

    Only completed members are drawn; None when there is none. A non-numeric varied key (an
    image file, a method) is drawn as categories in member order.
    """
    from porefsi.plot import _plt

    done = [(m, r) for m, r in zip(sweep.members, records, strict=True) if r and r.get("status") == "completed"]
    if not done:
        return None
    spec = sweep.plot
    others = [k for k in sweep.keys if k != spec.x]
    xs = [m.values[spec.x] for m, _ in done]
    numeric = all(_number(x) is not None for x in xs)
    cats = list(dict.fromkeys(str(x) for x in xs))
    plt = _plt()
    n = len(spec.y)
    ncol = min(3, n)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 3.6 * nrow), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    groups: dict = {}
    for m, r in done:
        groups.setdefault(tuple(m.values[k] for k in others), []).append((m, r))
    for ax, field in zip(axes.flat, spec.y, strict=False):
        for key, items in groups.items():
            pts = [(_x(m.values[spec.x], numeric, cats), _number((r["summary"] or {}).get(field))) for m, r in items]
            pts = sorted(p for p in pts if p[1] is not None)
            if not pts:
                continue
            lab = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(others, key, strict=True)) or None
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", ms=4, label=lab)
        ax.set_xscale("log" if spec.logx else "linear")
        if spec.logy:
            ax.set_yscale("log")
        if not numeric:
            ax.set_xticks(range(len(cats)), cats, rotation=60, ha="right", fontsize=7)
        ax.set_xlabel(spec.x)
        ax.set_title(field, fontsize=9)
        ax.grid(alpha=0.3, which="both")
        if others and len(groups) > 1:
            ax.legend(fontsize=6)
    fig.tight_layout()
    out = Path(path)
    with results.atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return out


def _x(v, numeric: bool, cats: list) -> float:
    return float(v) if numeric else float(cats.index(str(v)))
