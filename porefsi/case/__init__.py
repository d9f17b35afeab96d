"""Case files: read, validate and run them (the layer between the command line and the coupling).

:func:`load_case` reads a TOML case file into a :class:`Case`; :func:`problem_from_case` reads its
image and builds the coupled problem (through :func:`coupled_options`, the case as the
coupling's option objects); :func:`run_case` runs it into a run directory with checkpoints,
resume and figures. :func:`resolve_fidelity` applies a ``[fidelity]`` preset (``auto``: settings
chosen for an error tolerance or a CPU budget from a calibrated model; docs/fidelity.md).
"""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "Case": "porefsi.case.config",
    "load_case": "porefsi.case.config",
    "case_from_dict": "porefsi.case.config",
    "case_to_dict": "porefsi.case.config",
    "case_to_toml": "porefsi.case.config",
    "smoke_case": "porefsi.case.config",
    "schema_markdown": "porefsi.case.config",
    "ImageConfig": "porefsi.case.config",
    "FluidsConfig": "porefsi.case.config",
    "InterfaceConfig": "porefsi.case.config",
    "OutputConfig": "porefsi.case.config",
    "FidelityConfig": "porefsi.case.config",
    "FIDELITY_KEYS": "porefsi.case.config",
    "resolve_fidelity": "porefsi.case.fidelity",
    "FidelityChoice": "porefsi.case.fidelity",
    "problem_from_case": "porefsi.case.problem",
    "coupled_options": "porefsi.case.problem",
    "load_case_image": "porefsi.case.problem",
    "interface_options": "porefsi.case.problem",
    "run_case": "porefsi.case.run",
    "RunOutput": "porefsi.case.run",
}

__all__ = [
    "Case",
    "load_case",
    "case_from_dict",
    "case_to_dict",
    "case_to_toml",
    "smoke_case",
    "schema_markdown",
    "ImageConfig",
    "FluidsConfig",
    "InterfaceConfig",
    "OutputConfig",
    "FidelityConfig",
    "FIDELITY_KEYS",
    "resolve_fidelity",
    "FidelityChoice",
    "problem_from_case",
    "coupled_options",
    "load_case_image",
    "interface_options",
    "run_case",
    "RunOutput",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)
