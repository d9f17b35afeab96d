"""``porefsi solid`` through main(argv): summary keys, files, physics sanity, bad input."""

import json

import numpy as np
import pytest

from porefsi.cli import main
from porefsi.io.solid_vtk import read_solid_vtu


def test_solid_cli_json_and_vtu(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["solid", "--coarsen", "12", "--strain", "1e-3", "--axis", "x", "-o", str(out), "--json"])
    assert code == 0
    s = json.loads(capsys.readouterr().out)
    for key in ("n_nodes", "n_tets", "removed_solid_fraction", "effective_modulus_Pa", "max_displacement_m",
                "max_von_mises_Pa", "seconds"):
        assert key in s
    # the platen moves strain * L = 1e-3 * 0.6414 mm
    assert np.isclose(s["max_displacement_m"], 1e-3 * 120 * 5.345e-6, rtol=0.05)
    p, t, pd, cd = read_solid_vtu(out / "solid.vtu")
    # Voigt bound (rigorous, any microstructure): with rollers on the lateral faces the uniform
    # uniaxial strain of the solid is kinematically admissible, so the apparent modulus is at most
    # the solid fraction of the mesh times the grains' lambda + 2 mu = E(1-nu)/((1+nu)(1-2nu))
    # (25.57 GPa at E = 20 GPa, nu = 0.28); +1 % for the SVK nonlinearity at 1e-3 strain. A
    # connected solid at ~11 % mesh porosity keeps most of it (dilute spherical pores: M (1 - ~2 phi),
    # 0.87 of the bound): at least half. Measured 20.36 GPa = 0.90 of the bound (22.70 GPa).
    a, b, c = (p[t[:, k]] - p[t[:, 0]] for k in (1, 2, 3))
    solid_volume = np.abs(np.einsum("ij,ij->i", np.cross(a, b), c)).sum() / 6.0
    box_volume = (120 * 5.345e-6) ** 3
    E, nu = 20e9, 0.28
    voigt = solid_volume / box_volume * E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    assert 0.5 * voigt < s["effective_modulus_Pa"] < 1.01 * voigt, (s["effective_modulus_Pa"], voigt)
    assert len(p) == s["n_nodes"] and len(t) == s["n_tets"]
    assert pd["displacement"].shape == (s["n_nodes"], 3)
    assert np.isclose(cd["von_mises"].max(), s["max_von_mises_Pa"])
    assert json.loads((out / "summary.json").read_text())["n_tets"] == s["n_tets"]


def test_solid_cli_bad_input(capsys):
    assert main(["solid", "--coarsen", "12", "--poisson", "0.5"]) == 2
    assert "Poisson ratio" in capsys.readouterr().err
    assert main(["solid", "--coarsen", "0"]) == 2
    assert "coarsen" in capsys.readouterr().err


def test_solid_cli_slab_not_reaching_the_loaded_face(tmp_path, capsys):
    """Solid in the bottom 3 of 8 layers: exit 2 naming the image box face without solid (it used
    to exit 0 with E_eff = 25.5 GPa, the platen pressed on the slab's top surface)."""
    ph = np.ones((6, 6, 8), np.uint8)
    ph[:, :, :3] = 0
    path = tmp_path / "slab.npy"
    np.save(path, ph)
    assert main(["solid", str(path), "--voxel-size", "1e-6", "--coarsen", "1", "--json"]) == 2
    err = capsys.readouterr().err
    assert "no solid reaches the zmax face of the image box" in err and "another axis" in err
    assert main(["solid", str(path), "--voxel-size", "1e-6", "--coarsen", "1", "--axis", "x", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["effective_modulus_Pa"] > 0


def test_cli_commands_run_with_blas_pinned_to_one_thread(monkeypatch, capsys):
    """main() runs the command inside threadpool_limits(1) for every BLAS (numpy's and scipy's
    OpenBLAS), whatever the caller had, and restores the caller's setting afterwards. The caller
    here raises BLAS to 2 threads, so the test fails if main does not pin."""
    import scipy.linalg  # noqa: F401  (both BLAS libraries loaded, so the caller's limit reaches both)
    from threadpoolctl import threadpool_info, threadpool_limits

    import porefsi.cli._solid as solid_cmd

    seen = []

    def fake_run(args):
        import scipy.sparse.linalg  # noqa: F401  (what the solid command loads)

        seen.extend(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
        return 0

    monkeypatch.setattr(solid_cmd, "run", fake_run)
    with threadpool_limits(limits=2, user_api="blas"):
        before = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
        assert main(["solid", "--coarsen", "12"]) == 0
        after = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    assert before and set(before) == {2}
    assert len(seen) >= len(before) and set(seen) == {1}
    assert after == before


def _solid_json(capsys, *argv):
    assert main(["solid", "--coarsen", "12", "--json", *argv]) == 0
    return json.loads(capsys.readouterr().out)


def test_solid_cli_strain_material_axis_change_outputs_as_physics_says(tmp_path, capsys):
    """Non-default --strain, --material, --axis on the sample at coarsen 12 (4,440 tets).

    * strain 1e-4 -> 2e-4 (linear regime): the displacement field doubles to O(strain) (measured
      max deviation 3.4e-5 of the field's max), von Mises doubles, E_eff stays (5e-5 relative);
    * neo-Hookean vs SVK: both have the same small-strain tangent (Hooke), so E_eff agrees to
      O(strain): measured relative differences 2.5e-4 at 1e-4 and 5.0e-4 at 2e-4 (and 2.6e-2 at
      1e-2), i.e. proportional to the strain;
    * axis: the Berea frame is anisotropic: E_eff along x is 2.9 % below z (20.39 vs 21.01 GPa), y
      0.5 % below; far above the Newton tolerance (1e-8), and the reaction is along the loading axis.
    """
    from porefsi.io.solid_vtk import read_solid_vtu

    runs = {}
    for key, argv in {"svk1": ("--strain", "1e-4"), "svk2": ("--strain", "2e-4"),
                      "nh1": ("--strain", "1e-4", "--material", "neo-hookean"),
                      "nh2": ("--strain", "2e-4", "--material", "neo-hookean"),
                      "x": ("--strain", "1e-4", "--axis", "x")}.items():
        runs[key] = _solid_json(capsys, *argv, "-o", str(tmp_path / key))
        runs[key]["u"] = read_solid_vtu(tmp_path / key / "solid.vtu")[2]["displacement"]
    s1, s2 = runs["svk1"], runs["svk2"]
    strain = 1e-4
    assert s1["material"] != runs["nh1"]["material"]
    # linear regime: u(2 eps) = 2 u(eps) + O(eps^2 L)
    dev = np.abs(s2["u"] - 2 * s1["u"]).max() / np.abs(s2["u"]).max()
    assert dev <= 10 * strain
    assert s2["max_displacement_m"] == pytest.approx(2 * s1["max_displacement_m"], rel=1e-12)  # the platen
    assert s2["max_von_mises_Pa"] == pytest.approx(2 * s1["max_von_mises_Pa"], rel=10 * strain)
    assert s2["effective_modulus_Pa"] == pytest.approx(s1["effective_modulus_Pa"], rel=10 * strain)
    # neo-Hookean vs SVK: agree at small strain, the gap proportional to the strain
    gap1 = abs(runs["nh1"]["effective_modulus_Pa"] / s1["effective_modulus_Pa"] - 1)
    gap2 = abs(runs["nh2"]["effective_modulus_Pa"] / s2["effective_modulus_Pa"] - 1)
    assert 0 < gap1 <= 10 * strain
    assert gap2 / gap1 == pytest.approx(2.0, rel=0.1)
    # axis: the anisotropic frame gives a different modulus along x; the reaction is along x
    ex, ez = runs["x"]["effective_modulus_Pa"], s1["effective_modulus_Pa"]
    assert abs(ex / ez - 1) > 0.01
    assert runs["x"]["axis"] == "x" and runs["x"]["axial_reaction_N"] < 0
    ux = runs["x"]["u"]
    assert np.abs(ux[:, 0]).max() == pytest.approx(runs["x"]["max_displacement_m"], rel=1e-12)


def test_solid_cli_small_image_with_default_coarsen(tmp_path, capsys):
    """A 4^3 image (37.5 % solid) with the default --coarsen 5: one block, under half solid, so
    nothing is left; the message names that cause and the fix, and --coarsen 1 works."""
    ph = np.ones((4, 4, 4), np.uint8)
    ph[:, :, 0] = 0
    ph[:2, :, 1] = 0
    path = tmp_path / "small.npy"
    np.save(path, ph)
    assert main(["solid", str(path), "--voxel-size", "1e-6"]) == 2
    err = capsys.readouterr().err
    assert "no 5^3 block is at least 0.5 solid" in err and "--coarsen 1" in err
    assert main(["solid", str(path), "--voxel-size", "1e-6", "--coarsen", "1", "--axis", "x", "--json"]) == 0
