"""``porefsi solid`` through main(argv): summary keys, files, physics sanity, bad input."""

import json

import numpy as np

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
    # porous rock is softer than the grains' uniaxial-strain modulus lambda + 2 mu (29.4 GPa at
    # E = 20 GPa, nu = 0.28) and stiffer than zero; the platen moves strain * L = 1e-3 * 0.6414 mm
    assert 0 < s["effective_modulus_Pa"] < 29.4e9
    assert np.isclose(s["max_displacement_m"], 1e-3 * 120 * 5.345e-6, rtol=0.05)
    p, t, pd, cd = read_solid_vtu(out / "solid.vtu")
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
