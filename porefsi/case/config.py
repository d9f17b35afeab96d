"""Case files: TOML -> frozen, validated dataclasses.

A case file has one table per section below; every key is optional and defaults to the seed
paper's table 2 set-up on the built-in sample. Unknown sections or keys and out-of-range values
raise :class:`~porefsi.errors.ConfigError` naming the key. :func:`schema_markdown` renders the
reference table in the docs from the same definitions, so docs and code cannot disagree.

The ``[drainage]``, ``[solid]``, ``[network]`` and ``[coupling]`` sections are the coupling's own
option objects (:mod:`porefsi.coupling.options`; ``DrainageConfig`` etc. are their names here);
``[image]``, ``[fluids]``, ``[interface]`` and ``[output]`` are the case file's, turned into
options by :func:`porefsi.case.problem.coupled_options`. The bounds of the physical quantities are
the physics classes' (:attr:`Fluids.LIMITS <porefsi.flow.fluids.Fluids.LIMITS>`, the material's).
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

from porefsi._schema import Limits, check_value, describe_allowed, field_default, option
from porefsi.coupling.options import CouplingOptions, DrainageOptions, NetworkOptions, SolidOptions
from porefsi.errors import ConfigError
from porefsi.flow.fluids import Fluids

__all__ = [
    "Case",
    "ImageConfig",
    "FluidsConfig",
    "DrainageConfig",
    "SolidConfig",
    "InterfaceConfig",
    "CouplingConfig",
    "NetworkConfig",
    "OutputConfig",
    "FidelityConfig",
    "load_case",
    "case_from_dict",
    "case_to_dict",
    "case_to_toml",
    "schema_markdown",
    "smoke_case",
]

_f = option
_POSITIVE = Limits(0.0, None, lo_open=True)


@dataclasses.dataclass(frozen=True)
class ImageConfig:
    """Where the rock image comes from."""

    path: str = _f("", "image file; empty = the built-in 120³ Berea sample")
    voxel_size: float | None = _f(None, "voxel edge length (needed when the file carries none; 1e-10 to 1 m, "
                                  "a warning outside 1 nm - 1 mm)", limits=Limits(1e-10, 1.0), unit="m", optional=True)
    threshold: float | None = _f(None, "grey images: pore = value <= threshold", optional=True)
    pore_value: float | None = _f(None, "labelled images: the value that marks pore", optional=True)
    invert: bool = _f(False, "binary images: 0 is pore (default 1/True = pore)")
    crop: list = _f([], "[[x0, x1], [y0, y1], [z0, z1]] voxel bounds, integers with 0 <= x0 < x1 <= image size "
                    "(the size is checked when the image is read); empty = whole image", items="crop")
    axis: str = _f("x", "flow axis (inlet at its low face, outlet at its high face)", choices=("x", "y", "z"))


@dataclasses.dataclass(frozen=True)
class FluidsConfig:
    """The two fluids (paper section 3.1: water-wet drainage of water by oil)."""

    mu_w: float = _f(Fluids.mu_w, "wetting-phase viscosity (paper: 1 cP)", limits=Fluids.LIMITS["mu_w"], unit="Pa s")
    mu_n: float = _f(Fluids.mu_n, "non-wetting viscosity (paper: 10 cP)", limits=Fluids.LIMITS["mu_n"], unit="Pa s")
    sigma: float = _f(Fluids.sigma, "interfacial tension (oil-water; the paper gives none)",
                      limits=Fluids.LIMITS["sigma"], unit="N/m")
    theta_deg: float = _f(Fluids.theta_deg, "contact angle through the wetting phase (paper: 0)",
                          limits=Fluids.LIMITS["theta_deg"], unit="deg")


#: The coupling's option objects are the case file's sections of the same names.
DrainageConfig = DrainageOptions
SolidConfig = SolidOptions
NetworkConfig = NetworkOptions
CouplingConfig = CouplingOptions


@dataclasses.dataclass(frozen=True)
class InterfaceConfig:
    """Pore pressure -> nodal forces."""

    method: str = _f("traction", "traction = consistent wall traction on each pore's voxel faces (default: "
                     "0.29 vs the hull's 0.77 error at equal cost, docs/speed_accuracy.md); hull = the paper's "
                     "convex hull of test points",
                     choices=("hull", "traction"))
    n_test_points: int = _f(800, "hull only (ignored with traction): test points per pore sphere (paper: 800)",
                            limits=Limits(4))
    tolerance: float | None = _f(None, "hull only (ignored with traction): range of inclusivity ε (eq. 3.2); "
                                 "default 0.5 x pore radius", limits=Limits(0.0), unit="m", optional=True)
    seed: int = _f(0, "hull only (ignored with traction): seed of the test-point generator", limits=Limits(0))
    throat_forces: bool = _f(False, "hull only: also load the throat walls (the paper neglects them, section 3.2); "
                             "true with method = traction is an error (the traction already loads the whole wall "
                             "of each pore's voxel region, throats included)")


@dataclasses.dataclass(frozen=True)
class OutputConfig:
    """What is written, and when."""

    dir: str = _f("porefsi-out", "output directory (relative to the working directory)")
    snapshot_times: list = _f([1.0, 3.0, 5.0, 15.0], "times of 3-D snapshots and figures (paper fig. 7)",
                              unit="s", items="number", limits=Limits(0.0))
    checkpoint_every: int = _f(5, "write a checkpoint every N exchange steps", limits=Limits(1))
    figures: bool = _f(True, "write PNG figures (matplotlib curves, pyvista scenes)")
    vtk: bool = _f(True, "write ParaView series (.pvd + .vtu solid, .vtp network)")


#: The settings a fidelity preset chooses (``[fidelity]``; :mod:`porefsi.case.fidelity`). A case
#: file's own value of one of them wins over the preset: it is listed in ``fidelity.keep``.
FIDELITY_KEYS = ("solid.coarsen", "interface.method", "interface.n_test_points", "coupling.integrator",
                 "coupling.tdg_iterations", "coupling.tdg_load_rule", "network.update", "drainage.scheme",
                 "solid.response", "solid.mesh", "solid.coarsen_max", "solid.grading", "solid.refine",
                 "solid.ligaments")


@dataclasses.dataclass(frozen=True)
class FidelityConfig:
    """How much model the run gets (docs/fidelity.md).

    A preset chooses mesh, interface, integrator, network update, drainage scheme and solid
    response; a key the case file sets itself wins over the preset (it is listed in ``keep``). A
    top-level ``fidelity = "auto"`` is short for ``[fidelity] preset = "auto"``.
    """

    preset: str = _f("none", "none = the case's keys as they are (default); auto = chosen from the calibrated "
                     "error model for a target (tolerance or budget_s); fast = coarsen 6; accurate = coarsen 3; "
                     "paper = the seed paper's methods (hull, TDG left rule, re-extraction)",
                     choices=("none", "auto", "fast", "accurate", "paper"))
    tolerance: float | None = _f(None, "auto: target relative L2 error of the displacement (as in the "
                                 "speed-accuracy study), e.g. 0.3", limits=Limits(0.0, 10.0, lo_open=True),
                                 optional=True)
    budget_s: float | None = _f(None, "auto: CPU-time budget of the run (one thread), the most accurate "
                                "setting expected to fit", limits=_POSITIVE, unit="s", optional=True)
    keep: list = dataclasses.field(  # bookkeeping, not a setting: equal cases may differ in it
        default_factory=list, compare=False, metadata=_f([], "keys the preset leaves as the case sets them (filled "
                                                         "from the case file's own keys; written only with a preset; "
                                                         f"any of {', '.join(FIDELITY_KEYS)})", items="keys").metadata)


_SECTIONS: dict[str, type] = {
    "image": ImageConfig,
    "fluids": FluidsConfig,
    "drainage": DrainageConfig,
    "solid": SolidConfig,
    "interface": InterfaceConfig,
    "network": NetworkConfig,
    "coupling": CouplingConfig,
    "output": OutputConfig,
    "fidelity": FidelityConfig,
}


@dataclasses.dataclass(frozen=True)
class Case:
    """A whole simulation set-up (one field per case-file section)."""

    image: ImageConfig = dataclasses.field(default_factory=ImageConfig)
    fluids: FluidsConfig = dataclasses.field(default_factory=FluidsConfig)
    drainage: DrainageConfig = dataclasses.field(default_factory=DrainageConfig)
    solid: SolidConfig = dataclasses.field(default_factory=SolidConfig)
    interface: InterfaceConfig = dataclasses.field(default_factory=InterfaceConfig)
    network: NetworkConfig = dataclasses.field(default_factory=NetworkConfig)
    coupling: CouplingConfig = dataclasses.field(default_factory=CouplingConfig)
    output: OutputConfig = dataclasses.field(default_factory=OutputConfig)
    fidelity: FidelityConfig = dataclasses.field(default_factory=FidelityConfig)
    name: str = "default"

    def replace(self, **sections) -> Case:
        """Return a copy with whole sections or ``section={key: value}`` dicts replaced (validated).

        A fidelity-controlled key given in a ``section={key: value}`` dict joins ``fidelity.keep``
        (the caller set it: a preset leaves it alone).
        """
        d = case_to_dict(self)
        for sec, val in sections.items():
            if sec == "name":
                d["name"] = val
            elif isinstance(val, dict):
                d.setdefault(sec, {}).update(val)
            else:
                d[sec] = dataclasses.asdict(val)
        given = _fidelity_keys({s: v for s, v in sections.items() if isinstance(v, dict) and s != "fidelity"})
        fid = sections.get("fidelity")
        kept = fid["keep"] if isinstance(fid, dict) and "keep" in fid else self.fidelity.keep
        d["fidelity"]["keep"] = sorted(set(kept) | set(given))
        return case_from_dict(d, name=d.get("name", self.name))


def case_from_dict(data: dict, *, name: str = "case", where: str = "case") -> Case:
    """Build a validated :class:`Case` from nested dicts (as parsed from TOML).

    Raises
    ------
    ConfigError
        Unknown section or key, wrong type or out-of-range value; the message names the key.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a table of sections, got {type(data).__name__}")
    kwargs: dict[str, Any] = {}
    data = _with_fidelity_keep(data)
    for sec, val in data.items():
        if sec == "name":
            if not isinstance(val, str):
                raise ConfigError(f"{where}: name must be a string")
            name = val
            continue
        if sec not in _SECTIONS:
            raise ConfigError(f"{where}: unknown section [{sec}]; known sections: {', '.join(_SECTIONS)}")
        if not isinstance(val, dict):
            raise ConfigError(f"{where}: [{sec}] must be a table of keys")
        cls = _SECTIONS[sec]
        fields = {f.name: f for f in dataclasses.fields(cls)}
        vals = {}
        for key, v in val.items():
            if key not in fields:
                known = ", ".join(fields)
                raise ConfigError(f"{where}: unknown key {sec}.{key}; known keys in [{sec}]: {known}")
            vals[key] = check_value(sec, fields[key], v, where)
        kwargs[sec] = cls(**vals)
    case = Case(**kwargs, name=name)
    _cross_check(case, where)
    return case


def _fidelity_keys(data: dict) -> list[str]:
    """The fidelity-controlled keys (``section.key``) that ``data`` (sections of dicts) sets."""
    return sorted(f"{sec}.{k}" for sec, val in data.items() if isinstance(val, dict) for k in val
                  if f"{sec}.{k}" in FIDELITY_KEYS)


def _with_fidelity_keep(data: dict) -> dict:
    """``data`` with ``fidelity = "preset"`` expanded and ``fidelity.keep`` filled from its own keys."""
    fid = data.get("fidelity", {})
    if isinstance(fid, str):
        fid = {"preset": fid}
    if not isinstance(fid, dict) or "keep" in fid:
        return data if fid is data.get("fidelity", {}) else {**data, "fidelity": fid}
    return {**data, "fidelity": {**fid, "keep": _fidelity_keys(data)}}


def _check_fidelity(fc: FidelityConfig, where: str) -> None:
    bad = [k for k in fc.keep if k not in FIDELITY_KEYS]
    if bad:
        raise ConfigError(f"{where}: fidelity.keep names {bad[0]!r}, not a key a preset chooses; use any of "
                          f"{', '.join(FIDELITY_KEYS)}")
    if fc.tolerance is not None and fc.budget_s is not None:
        raise ConfigError(f"{where}: give fidelity.tolerance or fidelity.budget_s, not both (auto meets one target)")
    if fc.preset == "auto" and fc.tolerance is None and fc.budget_s is None:
        raise ConfigError(f"{where}: fidelity.preset = 'auto' needs a target: set fidelity.tolerance (relative "
                          "displacement error, e.g. 0.3) or fidelity.budget_s (CPU seconds)")
    if fc.preset != "auto" and (fc.tolerance is not None or fc.budget_s is not None):
        raise ConfigError(f"{where}: fidelity.tolerance and fidelity.budget_s are targets of preset 'auto' (got "
                          f"preset {fc.preset!r}); set fidelity.preset = 'auto' or drop the target")


def _cross_check(case: Case, where: str) -> None:
    _check_fidelity(case.fidelity, where)
    if case.interface.throat_forces and case.interface.method != "hull":
        raise ConfigError(
            f"{where}: interface.throat_forces = true needs interface.method = 'hull' (got "
            f"{case.interface.method!r}, whose wall traction already covers the throat walls); set "
            "throat_forces = false or method = 'hull'")
    if case.image.threshold is not None and case.image.pore_value is not None:
        raise ConfigError(f"{where}: give image.threshold or image.pore_value, not both")
    if case.coupling.exchange_dt > case.drainage.t_end:
        raise ConfigError(
            f"{where}: coupling.exchange_dt = {case.coupling.exchange_dt} s exceeds drainage.t_end = "
            f"{case.drainage.t_end} s; use a smaller exchange step"
        )


def load_case(path: str | Path) -> Case:
    """Read and validate a TOML case file.

    Raises
    ------
    ConfigError
        Missing file, TOML syntax error, unknown key or bad value (named).
    """
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"case file {str(p)!r} is a folder; give the path of a .toml case file")
    if not p.is_file():
        raise ConfigError(f"case file {str(p)!r} not found; give the path of a .toml case file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML ({exc})") from None
    except UnicodeDecodeError as exc:
        line = p.read_bytes()[: exc.start].count(b"\n") + 1
        raise ConfigError(f"{p}: not UTF-8 text (byte {exc.object[exc.start]:#04x} on line {line}); save the case "
                          "file as UTF-8 (TOML files are UTF-8)") from None
    except OSError as exc:
        raise ConfigError(f"cannot read case file {p}: {exc.strerror or exc}") from None
    case = case_from_dict(data, name=data.get("name", p.stem) if isinstance(data.get("name", ""), str)
                          else p.stem, where=str(p))
    # A relative image path is relative to the case file, so cases run from any directory.
    if case.image.path and not Path(case.image.path).is_absolute():
        case = case.replace(image={"path": str((p.parent / case.image.path).resolve())})
    return case


def case_to_dict(case: Case) -> dict:
    """Nested plain dict of every section (the inverse of :func:`case_from_dict`)."""
    out: dict[str, Any] = {"name": case.name}
    for sec in _SECTIONS:
        out[sec] = dataclasses.asdict(getattr(case, sec))
    if case.fidelity.preset == "none":  # without a preset the kept keys change nothing: not written
        del out["fidelity"]["keep"]
    return out


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to TOML")


def case_to_toml(case: Case) -> str:
    """TOML text of ``case`` with every key (unset optional keys are written as comments)."""
    d = case_to_dict(case)
    lines = [f"name = {_toml_value(d.pop('name'))}"]
    for sec, vals in d.items():
        lines.append(f"\n[{sec}]")
        for k, v in vals.items():
            lines.append(f"# {k} = (default)" if v is None else f"{k} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"


def schema_markdown() -> str:
    """Markdown reference of every section and key: default, unit, allowed values, meaning."""
    out = []
    for sec, cls in _SECTIONS.items():
        out.append(f"### `[{sec}]`\n\n{cls.__doc__}\n")
        out.append("| key | default | unit | allowed | meaning |\n|---|---|---|---|---|")
        for f in dataclasses.fields(cls):
            m = f.metadata
            default = field_default(f)
            allowed = describe_allowed(f)
            dv = "unset" if default is None else f"`{_toml_value(default)}`"
            out.append(f"| `{f.name}` | {dv} | {m['unit']} | {allowed} | {m['doc']} |")
        out.append("")
    return "\n".join(out)


def smoke_case(case: Case) -> Case:
    """A seconds-long version of ``case`` with the same physics and options.

    Two exchange steps, a coarse mesh (coarsening >= 10), at most 100 test points per pore; every
    other setting (interface method, network update, integrator, fluids, rates) is kept, so the
    smoke run exercises the same code paths as the full one.
    """
    dt = case.coupling.exchange_dt
    return case.replace(
        name=f"{case.name}-smoke",
        drainage={"t_end": min(case.drainage.t_end, 2 * dt)},
        solid={"coarsen": max(case.solid.coarsen, 10)},
        interface={"n_test_points": min(case.interface.n_test_points, 100)},
        output={"snapshot_times": [t for t in case.output.snapshot_times if t <= 2 * dt], "checkpoint_every": 1},
    )
