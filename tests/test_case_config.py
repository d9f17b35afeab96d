"""Case files: defaults are the paper's table 2, validation names the key, TOML round trip."""

import tomllib

import pytest

from porefsi.case.config import Case, case_from_dict, case_to_toml, load_case, schema_markdown
from porefsi.errors import ConfigError


def test_defaults_are_the_papers_table_2():
    c = Case()
    assert c.solid.E == 20e9 and c.solid.nu == 0.28
    assert c.drainage.rate == 1.25e-13 and c.drainage.t_end == 20.0
    assert c.fluids.mu_w == 1e-3 and c.fluids.mu_n == 1e-2
    assert c.interface.n_test_points == 800


def test_toml_round_trip(tmp_path):
    c = Case().replace(solid={"coarsen": 3, "material": "neo-hookean"}, interface={"tolerance": 2e-6})
    p = tmp_path / "c.toml"
    p.write_text(case_to_toml(c))
    back = load_case(p)
    assert back == c
    assert back.interface.tolerance == 2e-6 and back.solid.material == "neo-hookean"


# List-valued keys: each element is validated, the message names the key and the element.
LIST_ERRORS = [
    ({"output": {"snapshot_times": ["a"]}}, r"output\.snapshot_times\[0\] must be a finite number s, got 'a'"),
    ({"output": {"snapshot_times": [1.0, -2.0]}}, r"output\.snapshot_times\[1\] must be >= 0\.0 s"),
    ({"output": {"snapshot_times": [1.0, True]}}, r"output\.snapshot_times\[1\] must be a finite number"),
    ({"image": {"crop": [[0, 10.5], [0, 10], [0, 10]]}}, r"image\.crop bounds must be integers .* on x"),
    ({"image": {"crop": [[0, 10], [7, 7], [0, 10]]}}, r"image\.crop on y must satisfy 0 <= start < stop"),
    ({"image": {"crop": [[0, 10], [0, 10], [-2, 10]]}}, r"image\.crop on z must satisfy"),
    ({"image": {"crop": [[0, 10], [0, 10], ["0", 10]]}}, r"image\.crop bounds must be integers"),
]


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"solid": {"E": -1.0}}, r"solid\.E must be > 0"),
        ({"solid": {"youngs": 1.0}}, r"unknown key solid\.youngs"),
        ({"fluid": {}}, r"unknown section \[fluid\]"),
        ({"solid": {"order": 3}}, r"solid\.order = 3 is not one of"),
        ({"solid": {"nu": 0.5}}, r"solid\.nu must be > -1\.0, < 0\.5"),
        ({"interface": {"n_test_points": 1.5}}, r"interface\.n_test_points must be an integer"),
        ({"fluids": {"theta_deg": 90}}, r"fluids\.theta_deg must be >= 0\.0, < 90\.0"),
        ({"drainage": {"rate": 0}}, r"drainage\.rate must be > 0"),
        ({"output": {"figures": "yes"}}, r"output\.figures must be true or false"),
        ({"coupling": {"exchange_dt": 30.0}}, r"exceeds drainage\.t_end"),
        ({"image": {"crop": [[0, 10]]}}, r"image\.crop must be"),
    ] + LIST_ERRORS,
)
def test_bad_values_name_the_key(data, match):
    with pytest.raises(ConfigError, match=match):
        case_from_dict(data)


@pytest.mark.parametrize(("data", "match"), LIST_ERRORS)
def test_bad_list_elements_are_caught_by_the_loader(tmp_path, data, match):
    """List elements are validated when the file is read (they used to fail later with a
    TypeError traceback, or once the set-up had started, without the key's name)."""
    p = tmp_path / "c.toml"
    p.write_text(_toml(data))
    with pytest.raises(ConfigError, match=match):
        load_case(p)


@pytest.mark.parametrize(("data", "match"), [*LIST_ERRORS[:2], *LIST_ERRORS[3:4],
                                             ({"image": {"crop": [[0, 500], [0, 60], [0, 60]]}},
                                              r"image\.crop .* reaches beyond the image \(120 x 120 x 120")])
def test_cli_run_bad_list_is_one_line_exit_2(tmp_path, capsys, data, match):
    """Through ``porefsi run``: exit code 2, one line on stderr naming the key, no traceback
    (a crop beyond the image is found when the image is read, still before any computation)."""
    import re

    from porefsi.cli import main

    p = tmp_path / "c.toml"
    p.write_text(_toml(data))
    assert main(["run", str(p), "-o", str(tmp_path / "o"), "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and re.search(match, err), err


def _toml(data: dict) -> str:
    import json

    return "".join(f"[{sec}]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in vals.items())
                   for sec, vals in data.items())


def test_load_case_errors(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_case(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[solid\nE = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_case(bad)


def test_relative_image_path_is_relative_to_the_case_file(tmp_path):
    (tmp_path / "sub").mkdir()
    p = tmp_path / "sub" / "c.toml"
    p.write_text('[image]\npath = "rock.npz"\n')
    assert load_case(p).image.path == str((tmp_path / "sub" / "rock.npz").resolve())


def test_schema_reference_lists_every_key():
    md = schema_markdown()
    d = tomllib.loads(case_to_toml(Case()))
    for vals in d.values():
        if isinstance(vals, dict):
            for key in vals:
                assert f"| `{key}` |" in md


def test_physical_bounds_are_the_physics_classes():
    """The case file's bounds of the fluids and the material are those of Fluids and Material (issue 14:
    they used to be restated, as nu <= 0.4999 and theta <= 89.999): what one accepts the other accepts."""
    import dataclasses

    from porefsi.flow.fluids import Fluids
    from porefsi.solid.materials import Material, make_material

    ok = case_from_dict({"solid": {"nu": 0.49995, "E": 1e-3}, "fluids": {"theta_deg": 89.9995}})
    make_material(ok.solid.material, E=ok.solid.E, nu=ok.solid.nu)  # the physics class takes it too
    Fluids(**dataclasses.asdict(ok.fluids))
    for cls, section in ((Material, "solid"), (Fluids, "fluids")):
        for name, lim in cls.LIMITS.items():
            for bad in (lim.lo, lim.hi):
                if bad is None:
                    continue
                closed = (bad == lim.lo and not lim.lo_open) or (bad == lim.hi and not lim.hi_open)
                if closed:
                    case_from_dict({section: {name: bad}})
                else:
                    with pytest.raises(ConfigError, match=rf"{section}\.{name} must be"):
                        case_from_dict({section: {name: bad}})
