"""Case files: TOML -> frozen, validated dataclasses.

A case file has one table per section below; every key is optional and defaults to the seed
paper's table 2 set-up on the built-in sample. Unknown sections or keys and out-of-range values
raise :class:`~porefsi.errors.ConfigError` naming the key. :func:`schema_markdown` renders the
reference table in the docs from the same definitions, so docs and code cannot disagree.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

from porefsi.errors import ConfigError

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
    "load_case",
    "case_from_dict",
    "case_to_dict",
    "case_to_toml",
    "schema_markdown",
    "smoke_case",
]


def _f(default, doc: str, *, choices=None, lo=None, hi=None, lo_open=False, unit: str = "", optional=False,
       items=None):
    """A config field with its documentation and validation rule.

    ``items`` validates the elements of a list field: ``"number"`` (finite numbers, bounded by
    ``lo``/``hi``, stored as floats) or ``"crop"`` (empty, or three ``[start, stop]`` pairs of
    integers with ``0 <= start < stop``).
    """
    meta = {"doc": doc, "choices": choices, "lo": lo, "hi": hi, "lo_open": lo_open, "unit": unit,
            "optional": optional, "items": items}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@dataclasses.dataclass(frozen=True)
class ImageConfig:
    """Where the rock image comes from."""

    path: str = _f("", "image file; empty = the built-in 120³ Berea sample")
    voxel_size: float | None = _f(None, "voxel edge length (needed when the file carries none; 1e-10 to 1 m, "
                                  "a warning outside 1 nm - 1 mm)", lo=1e-10, hi=1.0, unit="m", optional=True)
    threshold: float | None = _f(None, "grey images: pore = value <= threshold", optional=True)
    pore_value: float | None = _f(None, "labelled images: the value that marks pore", optional=True)
    invert: bool = _f(False, "binary images: 0 is pore (default 1/True = pore)")
    crop: list = _f([], "[[x0, x1], [y0, y1], [z0, z1]] voxel bounds, integers with 0 <= x0 < x1 <= image size "
                    "(the size is checked when the image is read); empty = whole image", items="crop")
    axis: str = _f("x", "flow axis (inlet at its low face, outlet at its high face)", choices=("x", "y", "z"))


@dataclasses.dataclass(frozen=True)
class FluidsConfig:
    """The two fluids (paper section 3.1: water-wet drainage of water by oil)."""

    mu_w: float = _f(1.0e-3, "wetting-phase viscosity (paper: 1 cP)", lo=0.0, lo_open=True, unit="Pa s")
    mu_n: float = _f(1.0e-2, "non-wetting viscosity (paper: 10 cP)", lo=0.0, lo_open=True, unit="Pa s")
    sigma: float = _f(0.03, "interfacial tension (oil-water; the paper gives none)", lo=0.0, lo_open=True,
                      unit="N/m")
    theta_deg: float = _f(0.0, "contact angle through the wetting phase (paper: 0)", lo=0.0, hi=89.999,
                          unit="deg")


@dataclasses.dataclass(frozen=True)
class DrainageConfig:
    """Injection of the non-wetting fluid."""

    rate: float = _f(1.25e-13, "volumetric injection rate (paper case A)", lo=0.0, lo_open=True,
                     unit="m^3/s")
    t_end: float = _f(20.0, "injection time (paper: 20 s)", lo=0.0, lo_open=True, unit="s")
    scheme: str = _f("exact", "exact = a pressure solve after every event (the reference); adaptive = quasi-static "
                     "fills in certified batches, local pressure updates elsewhere (docs/drainage.md)",
                     choices=("exact", "adaptive"))


@dataclasses.dataclass(frozen=True)
class SolidConfig:
    """The rock frame: mesh, material, mechanical loading."""

    coarsen: int = _f(5, "block-coarsening factor of the image before meshing (5: the paper's mesh size, "
                      "~57k tets on the 120³ sample)", lo=1)
    order: int = _f(1, "finite-element order (1 = P1, 2 = P2)", choices=(1, 2))
    material: str = _f("svk", "hyperelastic law", choices=("svk", "neo-hookean"))
    E: float = _f(20.0e9, "Young's modulus (paper: 20 GPa)", lo=0.0, lo_open=True, unit="Pa")
    nu: float = _f(0.28, "Poisson's ratio (paper: 0.28)", lo=-0.999, hi=0.4999)
    density: float = _f(2650.0, "grain density (quartz sandstone)", lo=0.0, lo_open=True, unit="kg/m^3")
    linear_solver: str = _f("direct", "solid linear solves: direct = sparse LU factorised once and reused while the "
                            "tangent holds (fastest to ~1e5 dofs); amg = CG + smoothed aggregation (large meshes); "
                            "jacobi = Jacobi-CG; auto = AMG-CG for a matrix's first 20 solves, then a reused LU "
                            "of it up to 1e5 dofs",
                            choices=("direct", "amg", "jacobi", "auto"))
    load_axis: str = _f("z", "axis of the mechanical load (fixed low face, moving high face)",
                        choices=("x", "y", "z"))
    strain_rate: float = _f(0.0, "compressive strain rate on the high face (paper section 3.3)", lo=0.0,
                            unit="1/s")


@dataclasses.dataclass(frozen=True)
class InterfaceConfig:
    """Pore pressure -> nodal forces."""

    method: str = _f("traction", "traction = consistent wall traction on each pore's voxel faces (default: "
                     "0.29 vs the hull's 0.77 error at equal cost, docs/speed_accuracy.md); hull = the paper's "
                     "convex hull of test points",
                     choices=("hull", "traction"))
    n_test_points: int = _f(800, "hull only (ignored with traction): test points per pore sphere (paper: 800)",
                            lo=4)
    tolerance: float | None = _f(None, "hull only (ignored with traction): range of inclusivity ε (eq. 3.2); "
                                 "default 0.5 x pore radius", lo=0.0, unit="m", optional=True)
    seed: int = _f(0, "hull only (ignored with traction): seed of the test-point generator", lo=0)
    throat_forces: bool = _f(False, "hull only: also load the throat walls (the paper neglects them, section 3.2); "
                             "true with method = traction is an error (the traction already loads the whole wall "
                             "of each pore's voxel region, throats included)")


@dataclasses.dataclass(frozen=True)
class NetworkConfig:
    """How the pore network follows the deforming solid."""

    update: str = _f("geometric", "reextract = paper (re-extraction with pre-coupling iterations); "
                     "geometric = move/resize pores from wall displacements; none = one-way",
                     choices=("reextract", "geometric", "none"))
    precoupling_tol: float = _f(0.01, "tolerance on the mean-pore-size change E_a (eq. 3.3)", lo=0.0,
                                lo_open=True)
    precoupling_max_iter: int = _f(10, "maximum pre-coupling re-extractions", lo=1)
    conductance: str = _f("shape_factor", "conduit model of every flow computation: shape_factor = Valvatne-Blunt "
                          "sections measured from the image (agrees with the rock, docs/extraction.md); paper = "
                          "circular cylinders of the inscribed radius (the seed paper's model)",
                          choices=("shape_factor", "paper"))


@dataclasses.dataclass(frozen=True)
class CouplingConfig:
    """The staggered two-way coupling loop (paper algorithm 1)."""

    exchange_dt: float = _f(1.0, "exchange (coupling) time step", lo=0.0, lo_open=True, unit="s")
    integrator: str = _f("static", "solid time integrator: static (default; at ωΔt ~ 1e7 it matches 2-pass TDG to "
                         "1e-15 for 12-20 % less CPU, docs/speed_accuracy.md) or tdg (the paper's, with inertia)",
                         choices=("tdg", "static"))
    tdg_iterations: int = _f(2, "Nørsett predictor-corrector passes (2 = third order)", choices=(1, 2))
    tdg_load_rule: str = _f("right", "TDG load samples: right = t+Δt/3, t+Δt (third order for the quasi-static "
                            "response of a stiff solid); left = t, t+2Δt/3 (the paper; second order there)",
                            choices=("right", "left"))
    subiterations: int = _f(1, "fluid-solid sub-iterations per exchange step (1 = explicit staggering)",
                            lo=1)
    relaxation: str = _f("aitken", "sub-iteration relaxation", choices=("none", "aitken"))
    subiteration_tol: float = _f(1e-6, "relative displacement change that ends sub-iterations", lo=0.0,
                                 lo_open=True)


@dataclasses.dataclass(frozen=True)
class OutputConfig:
    """What is written, and when."""

    dir: str = _f("porefsi-out", "output directory (relative to the working directory)")
    snapshot_times: list = _f([1.0, 3.0, 5.0, 15.0], "times of 3-D snapshots and figures (paper fig. 7)",
                              unit="s", items="number", lo=0.0)
    checkpoint_every: int = _f(5, "write a checkpoint every N exchange steps", lo=1)
    figures: bool = _f(True, "write PNG figures (matplotlib curves, pyvista scenes)")
    vtk: bool = _f(True, "write ParaView series (.pvd + .vtu solid, .vtp network)")


_SECTIONS: dict[str, type] = {
    "image": ImageConfig,
    "fluids": FluidsConfig,
    "drainage": DrainageConfig,
    "solid": SolidConfig,
    "interface": InterfaceConfig,
    "network": NetworkConfig,
    "coupling": CouplingConfig,
    "output": OutputConfig,
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
    name: str = "default"

    def replace(self, **sections) -> Case:
        """Return a copy with whole sections or ``section={key: value}`` dicts replaced (validated)."""
        d = case_to_dict(self)
        for sec, val in sections.items():
            if sec == "name":
                d["name"] = val
            elif isinstance(val, dict):
                d.setdefault(sec, {}).update(val)
            else:
                d[sec] = dataclasses.asdict(val)
        return case_from_dict(d, name=d.get("name", self.name))


def _check(section: str, field: dataclasses.Field, value: Any, where: str) -> Any:
    key = f"{section}.{field.name}"
    m = field.metadata
    default = field.default if field.default is not dataclasses.MISSING else field.default_factory()
    if value is None:
        if m["optional"]:
            return None
        raise ConfigError(f"{where}: {key} must be set (default {default!r})")
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: {key} must be true or false, got {value!r}")
        return value
    if isinstance(default, int) and not isinstance(default, bool):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: {key} must be an integer, got {value!r}")
    elif isinstance(default, float) or (default is None and field.type.startswith("float")):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: {key} must be a number{_unit(m)}, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{where}: {key} must be finite, got {value!r}")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where}: {key} must be a string, got {value!r}")
    elif isinstance(default, list):
        if not isinstance(value, list):
            raise ConfigError(f"{where}: {key} must be a list, got {value!r}")
        return _check_items(key, m, value, where)
    if m["choices"] is not None and value not in m["choices"]:
        raise ConfigError(f"{where}: {key} = {value!r} is not one of {list(m['choices'])}")
    lo, hi = m["lo"], m["hi"]
    if lo is not None and (value < lo or (m["lo_open"] and value == lo)):
        op = ">" if m["lo_open"] else ">="
        raise ConfigError(f"{where}: {key} must be {op} {lo}{_unit(m)}, got {value!r}")
    if hi is not None and value > hi:
        raise ConfigError(f"{where}: {key} must be <= {hi}{_unit(m)}, got {value!r}")
    return value


def _check_items(key: str, m: dict, value: list, where: str) -> list:
    """Validate the elements of list field ``key`` by its ``items`` rule; return the list."""
    if m["items"] == "number":
        out = []
        lo, hi = m["lo"], m["hi"]
        for i, x in enumerate(value):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise ConfigError(f"{where}: {key}[{i}] must be a finite number{_unit(m)}, got {x!r}")
            if lo is not None and (x < lo or (m["lo_open"] and x == lo)):
                op = ">" if m["lo_open"] else ">="
                raise ConfigError(f"{where}: {key}[{i}] must be {op} {lo}{_unit(m)}, got {x!r}")
            if hi is not None and x > hi:
                raise ConfigError(f"{where}: {key}[{i}] must be <= {hi}{_unit(m)}, got {x!r}")
            out.append(float(x))
        return out
    if m["items"] == "crop" and value:
        form = "[[x0, x1], [y0, y1], [z0, z1]] (voxel indices, integers, 0 <= start < stop)"
        if len(value) != 3 or any(not isinstance(c, list) or len(c) != 2 for c in value):
            raise ConfigError(f"{where}: {key} must be {form}, got {value!r}")
        for ax, (a, b) in zip("xyz", value, strict=True):
            if any(isinstance(v, bool) or not isinstance(v, int) for v in (a, b)):
                raise ConfigError(f"{where}: {key} bounds must be integers (voxel indices), got [{a!r}, {b!r}] "
                                  f"on {ax}; write e.g. [[0, 60], [0, 60], [0, 60]]")
            if not 0 <= a < b:
                raise ConfigError(f"{where}: {key} on {ax} must satisfy 0 <= start < stop, got [{a}, {b}]")
        return [list(c) for c in value]
    return value


def _unit(meta) -> str:
    return f" {meta['unit']}" if meta["unit"] else ""


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
            vals[key] = _check(sec, fields[key], v, where)
        kwargs[sec] = cls(**vals)
    case = Case(**kwargs, name=name)
    _cross_check(case, where)
    return case


def _cross_check(case: Case, where: str) -> None:
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
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            allowed = ""
            if m["choices"] is not None:
                allowed = ", ".join(f"`{c}`" for c in m["choices"])
            elif m["lo"] is not None or m["hi"] is not None:
                parts = []
                if m["lo"] is not None:
                    parts.append(f"{'>' if m['lo_open'] else '>='} {m['lo']}")
                if m["hi"] is not None:
                    parts.append(f"<= {m['hi']}")
                allowed = ", ".join(parts)
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
