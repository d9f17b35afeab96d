"""Sweep files: TOML -> a validated list of member cases.

A sweep file has a ``[base]`` table (``case = "path.toml"`` relative to the sweep file, inline
case keys that override it, ``smoke = true`` for the seconds-long variant of every member), a
``[vary]`` table of dotted case keys to value lists (combined as a product, or element-wise with
``mode = "zip"``; an optional ``label`` list names the members of a zip) and an optional
``[plot]`` table. Everything is checked here, before any member runs or any folder changes:
unknown tables or keys, empty or unequal lists, keys the case schema does not know, values the
case validation refuses (every member is built through :func:`porefsi.case.config.case_from_dict`)
and image files that do not exist. Errors are one-line :class:`~porefsi.errors.ConfigError`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
import re
import tomllib
from pathlib import Path
from typing import Any

from porefsi.case.config import FIDELITY_KEYS, Case, case_from_dict, case_to_dict, load_case, smoke_case
from porefsi.errors import ConfigError

__all__ = ["Member", "Sweep", "PlotSpec", "load_sweep", "sweep_from_dict", "member_name", "SUMMARY_NUMBERS"]

#: The numeric fields of a member's ``summary.json`` (:func:`porefsi.case.run.run_case`) that a
#: ``[plot]`` table may name (``sweep.csv`` holds every summary field, these and the rest).
SUMMARY_NUMBERS = ("wall_seconds", "cpu_seconds", "n_pores", "n_throats", "n_nodes", "n_tets",
                   "removed_solid_fraction", "n_exchange_steps", "t_end_s", "final_sw", "breakthrough_time_s",
                   "max_displacement_m", "max_von_mises_Pa", "permeability_initial_m2", "permeability_final_m2",
                   "mass_balance_error", "load_balance_error", "interface_unloaded_pores")
#: What ``[plot]`` draws when it names nothing.
DEFAULT_PLOT_Y = ("max_displacement_m", "max_von_mises_Pa", "final_sw", "permeability_final_m2", "cpu_seconds")
#: Longest member folder name (the varied values are abbreviated past it, with a digest).
MAX_NAME = 80

_TOP = ("base", "vary", "plot")
_BASE_KEYS = ("case", "smoke")
_PLOT_KEYS = ("x", "y", "logx", "logy")


@dataclasses.dataclass(frozen=True)
class Member:
    """One member of a sweep: its index, folder name, varied values and whole case."""

    index: int
    name: str
    values: dict  # dotted case key -> value, in [vary] order
    case: Case
    label: str | None = None


@dataclasses.dataclass(frozen=True)
class PlotSpec:
    """The ``[plot]`` table: summary fields ``y`` against varied key ``x``."""

    x: str
    y: tuple
    logx: bool
    logy: bool


@dataclasses.dataclass(frozen=True)
class Sweep:
    """A validated sweep: the members and how to plot them."""

    members: tuple
    keys: tuple  # varied dotted keys, in file order
    mode: str  # "product" or "zip"
    smoke: bool
    plot: PlotSpec
    source: str = ""  # the file it came from ("" for a dict)

    def design(self) -> list[dict]:
        """Plain data that identifies the sweep's results: every member's name and whole case."""
        return [{"index": m.index, "name": m.name, "case": case_to_dict(m.case)} for m in self.members]


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a TOML sweep file (paths in it are relative to its folder).

    Raises
    ------
    ConfigError
        Missing or unreadable file, bad TOML, or any problem :func:`sweep_from_dict` finds.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"sweep file {str(p)!r} not found; give the path of a .toml sweep file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML ({exc})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not UTF-8 text; save the sweep file as UTF-8 (TOML files are UTF-8)") from None
    except OSError as exc:
        raise ConfigError(f"cannot read sweep file {p}: {exc.strerror or exc}") from None
    return sweep_from_dict(data, base_dir=p.resolve().parent, where=str(p))


def sweep_from_dict(data: dict, *, base_dir: str | Path = ".", where: str = "sweep") -> Sweep:
    """Build a validated :class:`Sweep` from nested dicts (as parsed from TOML).

    Parameters
    ----------
    data : dict
        ``{"base": {...}, "vary": {...}, "plot": {...}}``.
    base_dir : path
        Folder that relative paths (``base.case``, ``image.path`` values) are relative to.
    where : str
        Names the source in error messages.

    Raises
    ------
    ConfigError
        The message names the table, key or member at fault and the fix.
    """
    base_dir = Path(base_dir)
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected tables [base], [vary], [plot]")
    for k in data:
        if k not in _TOP:
            hint = " (put mode in [vary])" if k == "mode" else ""
            raise ConfigError(f"{where}: unknown table or key {k!r}{hint}; a sweep file has [base], [vary] and "
                              "an optional [plot]")
    for k in _TOP:
        if not isinstance(data.get(k, {}), dict):
            raise ConfigError(f"{where}: {k} must be a table ([{k}])")
    base, smoke = _base_case(data.get("base", {}), base_dir, where)
    keys, rows, labels, mode = _combinations(data.get("vary", {}), base_dir, where)
    members = _members(base, smoke, keys, rows, labels, where)
    plot = _plot(data.get("plot", {}), keys, members, where)
    return Sweep(members=tuple(members), keys=tuple(keys), mode=mode, smoke=smoke, plot=plot, source=where)


def _base_case(tab: dict, base_dir: Path, where: str) -> tuple[Case, bool]:
    """The base case: the case file (if any) with the inline keys over it."""
    inline = {k: v for k, v in tab.items() if k not in _BASE_KEYS}
    smoke = tab.get("smoke", False)
    if not isinstance(smoke, bool):
        raise ConfigError(f"{where}: base.smoke must be true or false, got {smoke!r}")
    if "case" in tab:
        if not isinstance(tab["case"], str) or not tab["case"]:
            raise ConfigError(f"{where}: base.case must be the path of a case file, got {tab['case']!r}")
        cp = Path(tab["case"])
        case = load_case(cp if cp.is_absolute() else base_dir / cp)
    else:
        case = Case()
    if isinstance(inline.get("fidelity"), str):  # fidelity = "auto" is short for the section
        inline["fidelity"] = {"preset": inline["fidelity"]}
    d = case_to_dict(case)
    # a preset leaves alone the keys the case file or the inline table set, and only those
    own = {f"{sec}.{k}" for sec, val in inline.items() if isinstance(val, dict) for k in val} & set(FIDELITY_KEYS)
    d["fidelity"]["keep"] = sorted(set(case.fidelity.keep) | own)
    for sec, val in inline.items():
        if sec == "name":
            d["name"] = val
        elif isinstance(val, dict) and isinstance(d.get(sec), dict):
            d[sec].update(_resolve_paths(sec, val, base_dir))
        else:
            d[sec] = val  # case_from_dict names what is wrong with it
    return case_from_dict(d, name=case.name, where=f"{where}: [base]"), smoke


def _resolve_paths(sec: str, val: dict, base_dir: Path) -> dict:
    """``image.path`` relative to the sweep file, as ``load_case`` does for case files."""
    if sec == "image" and isinstance(val.get("path"), str) and val["path"] and not Path(val["path"]).is_absolute():
        return {**val, "path": str((base_dir / val["path"]).resolve())}
    return val


def _flatten(tab: dict, prefix: str = "") -> dict:
    """``{"drainage": {"rate": [...]}}`` (TOML's bare dotted keys) -> ``{"drainage.rate": [...]}``."""
    out = {}
    for k, v in tab.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _combinations(tab: dict, base_dir: Path, where: str) -> tuple[list, list, list | None, str]:
    """(varied keys, one tuple of values per member, labels or None, mode) of the [vary] table."""
    tab = dict(tab)
    mode = tab.pop("mode", "product")
    if mode not in ("product", "zip"):
        raise ConfigError(f"{where}: vary.mode = {mode!r} is not one of ['product', 'zip']")
    labels = tab.pop("label", None)
    flat = _flatten(tab)
    if not flat:
        raise ConfigError(f"{where}: [vary] names no case key; add e.g. \"drainage.rate\" = [1.25e-13, 2.5e-13]")
    for key, vals in flat.items():
        if key.count(".") != 1:
            raise ConfigError(f"{where}: vary key {key!r} must be section.key (e.g. \"drainage.rate\")")
        if not isinstance(vals, list) or not vals:
            raise ConfigError(f"{where}: vary.{key} must be a non-empty list of values, got {vals!r}")
        if key == "image.path":
            flat[key] = [str((base_dir / v).resolve()) if isinstance(v, str) and v and not Path(v).is_absolute()
                         else v for v in vals]
    keys = list(flat)
    if mode == "zip":
        lens = {k: len(v) for k, v in flat.items()}
        if len(set(lens.values())) > 1:
            raise ConfigError(f"{where}: mode = \"zip\" pairs the lists element by element, but their lengths "
                              f"differ: {', '.join(f'{k} {n}' for k, n in lens.items())}; give every list the "
                              "same length (or use the default mode, the product)")
        rows = list(zip(*flat.values(), strict=True))
    else:
        rows = list(itertools.product(*flat.values()))
    if labels is not None:
        if mode != "zip" or not isinstance(labels, list) or len(labels) != len(rows) or \
                not all(isinstance(s, str) and s for s in labels) or len(set(labels)) != len(labels):
            raise ConfigError(f"{where}: vary.label must be a list of {len(rows)} distinct non-empty names, one per "
                              "member, and needs mode = \"zip\"")
    return keys, rows, labels, mode


def _members(base: Case, smoke: bool, keys: list, rows: list, labels: list | None, where: str) -> list[Member]:
    """Every member's validated case (smoke applied after the varied values)."""
    base_d = case_to_dict(base)
    width = len(str(len(rows) - 1))
    out = []
    for i, row in enumerate(rows):
        values = dict(zip(keys, row, strict=True))
        d = {s: dict(v) if isinstance(v, dict) else v for s, v in base_d.items()}
        for key, v in values.items():
            sec, k = key.split(".")
            if sec not in d or not isinstance(d[sec], dict):
                case_from_dict({sec: {}}, where=f"{where}: vary")  # names the unknown section
            d[sec][k] = v
        _keep_varied(d, values)
        label = labels[i] if labels else None
        name = member_name(i, values, width, label)
        d["name"] = f"{base.name}-{name}"
        case = case_from_dict(d, where=f"{where}: member {name}")
        if smoke:
            case = smoke_case(case)
        if case.image.path and not Path(case.image.path).exists():
            raise ConfigError(f"{where}: member {name}: image.path {case.image.path!r} does not exist; fix the path "
                              "(relative paths are relative to the sweep file)")
        out.append(Member(i, name, values, case, label))
    return out


def _keep_varied(d: dict, values: dict) -> None:
    """List the varied keys a fidelity preset would choose in ``d``'s ``fidelity.keep`` (in place).

    A member's varied value is the sweep's explicit setting: the base case's preset must not
    override it (the same rule as a case file's own keys, :data:`porefsi.case.config.FIDELITY_KEYS`).
    """
    fid = d.get("fidelity")
    varied = [k for k in values if k in FIDELITY_KEYS]
    if varied and isinstance(fid, dict) and "keep" in fid:
        d["fidelity"] = {**fid, "keep": sorted(set(fid["keep"]) | set(varied))}


def _token(v: Any, path: bool = False) -> str:
    """A short, filesystem-safe text of one varied value (of a file: its name without suffix)."""
    if isinstance(v, bool):
        s = "true" if v else "false"
    elif isinstance(v, float):
        s = f"{v:.6g}"
    elif path and isinstance(v, str):
        s = Path(v).stem if v else "builtin"  # an empty image.path: the built-in sample
    else:
        s = str(v)
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", s).strip("_.") or "_"


def member_name(index: int, values: dict, width: int = 1, label: str | None = None) -> str:
    """Folder name of a member: its index, then its label or ``key=value`` pairs, filesystem-safe.

    E.g. ``03-rate=5e-11,exchange_dt=0.05``. Stable (a function of the index and the values
    only); at most :data:`MAX_NAME` characters (longer ones keep their start and add a digest of
    the values, so two members never share a folder).
    """
    head = f"{index:0{width}d}"
    if label is not None:
        body = _token(label)
    else:
        body = ",".join(f"{k.split('.')[-1]}={_token(v, k.endswith('path'))}" for k, v in values.items())
    name = f"{head}-{body}" if body else head
    if len(name) > MAX_NAME:
        digest = hashlib.sha1(repr(sorted(values.items())).encode()).hexdigest()[:8]
        name = f"{name[:MAX_NAME - 9]}~{digest}"
    return name


def _plot(tab: dict, keys: list, members: list, where: str) -> PlotSpec:
    """The validated [plot] table (defaults: the first varied key, :data:`DEFAULT_PLOT_Y`)."""
    for k in tab:
        if k not in _PLOT_KEYS:
            raise ConfigError(f"{where}: unknown key plot.{k}; known keys in [plot]: {', '.join(_PLOT_KEYS)}")
    x = tab.get("x", keys[0])
    if x not in keys:
        raise ConfigError(f"{where}: plot.x = {x!r} is not a varied key; varied keys: {', '.join(keys)}")
    y = tab.get("y", list(DEFAULT_PLOT_Y))
    if isinstance(y, str):
        y = [y]
    if not isinstance(y, list) or not y or any(f not in SUMMARY_NUMBERS for f in y):
        raise ConfigError(f"{where}: plot.y must name summary numbers among {', '.join(SUMMARY_NUMBERS)}; got {y!r}")
    xs = [m.values[x] for m in members]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    default_logx = numeric and min(xs) > 0 and max(xs) / min(xs) >= 100 if xs else False
    logx, logy = tab.get("logx", default_logx), tab.get("logy", False)
    for k, v in (("logx", logx), ("logy", logy)):
        if not isinstance(v, bool):
            raise ConfigError(f"{where}: plot.{k} must be true or false, got {v!r}")
    if logx and not (numeric and all(v > 0 and math.isfinite(v) for v in xs)):
        raise ConfigError(f"{where}: plot.logx = true needs positive numbers in {x}")
    return PlotSpec(x=x, y=tuple(y), logx=logx, logy=logy)
