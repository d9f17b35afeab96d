"""``porefsi extract``, ``porefsi permeability`` and the interim ``porefsi run``, called through ``main(argv)``."""

import json

import numpy as np
import pytest

from porefsi import __version__
from porefsi.cli import main
from porefsi.flow.permeability import absolute_permeability
from porefsi.image.ops import percolating_cluster
from porefsi.image.synthetic import sphere_lattice
from porefsi.image.voxel_image import VoxelImage
from porefsi.network.convert import load_network, read_statoil
from porefsi.network.extract import extract_network

VS = 1e-5


LATTICE = sphere_lattice(n=(3, 3, 2), voxel_size=VS)  # 18 spheres, 33 cylinders, closed-form geometry


def lattice_image():
    return np.array(LATTICE.image.phases)


@pytest.fixture(scope="module")
def image_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("img") / "lattice.npz"
    np.savez(p, image=lattice_image(), voxel_size_m=VS)
    return p


def _json(capsys):
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1, out
    return json.loads(out[0])


def _fails(capsys, argv, *words):
    code = main(argv)
    cap = capsys.readouterr()
    assert code == 2, (code, cap)
    assert "Traceback" not in cap.err and cap.out == ""
    errs = [ln for ln in cap.err.splitlines() if "error:" in ln]
    assert len(errs) == 1, cap.err
    for w in words:
        assert w.lower() in errs[0].lower(), (w, errs[0])
    return errs[0]


def test_help_and_version(capsys):
    assert main(["--help"]) == 0
    assert "extract" in capsys.readouterr().out
    assert main(["--version"]) == 0
    assert __version__ in capsys.readouterr().out
    for cmd in ("extract", "permeability", "run"):
        assert main([cmd, "--help"]) == 0
        assert "--json" in capsys.readouterr().out


def test_extract_json_and_outputs(image_file, tmp_path, capsys):
    net_path, vtp, prefix = tmp_path / "net.npz", tmp_path / "net.vtp", tmp_path / "pn"
    argv = ["extract", str(image_file), "--axis", "y", "-o", str(net_path), "--vtk", str(vtp),
            "--statoil", str(prefix), "--json"]
    assert main(argv) == 0
    s = _json(capsys)
    for k in ("n_pores", "n_throats", "porosity", "voxel_size_m", "seconds", "mean_coordination",
              "removed_fraction", "network_file", "vtk_file"):
        assert k in s, k
    img = lattice_image()
    assert s["voxel_size_m"] == VS and s["porosity"] == pytest.approx(LATTICE.porosity, rel=1e-15, abs=0)
    # One pore per sphere and one throat per cylinder of the construction.
    assert (s["n_pores"], s["n_throats"]) == (len(LATTICE.pore_radius), len(LATTICE.throat_conns))
    assert s["removed_fraction"] == 0.0  # the lattice is one percolating cluster
    # The same pipeline through the library gives the same network, and the file holds it.
    ext = extract_network(percolating_cluster(VoxelImage(img, VS), "y").image)
    net = load_network(net_path)
    assert (s["n_pores"], s["n_throats"]) == (net.n_pores, net.n_throats) == (ext.network.n_pores,
                                                                                ext.network.n_throats)
    np.testing.assert_array_equal(net.pore_coords, ext.network.pore_coords)
    assert s["mean_coordination"] == pytest.approx(2 * net.n_throats / net.n_pores, rel=1e-15, abs=0)
    assert vtp.stat().st_size > 0
    back = read_statoil(prefix, voxel_size=VS, axis="y")
    np.testing.assert_array_equal(back.throat_conns, net.throat_conns)


def test_permeability_from_image_and_from_network_file_agree(image_file, tmp_path, capsys):
    net_path = tmp_path / "net.npz"
    assert main(["extract", str(image_file), "-o", str(net_path), "--json"]) == 0
    capsys.readouterr()
    assert main(["permeability", str(image_file), "--json"]) == 0
    a = _json(capsys)
    assert main(["permeability", str(net_path), "--json"]) == 0
    b = _json(capsys)
    for s in (a, b):
        for k in ("permeability_m2", "permeability_mD", "n_pores", "seconds"):
            assert k in s, k
    assert a["permeability_m2"] == b["permeability_m2"] > 0
    assert a["permeability_mD"] == pytest.approx(a["permeability_m2"] / 9.869233e-16, rel=1e-15, abs=0)
    ref = absolute_permeability(load_network(net_path), "x")
    assert a["permeability_m2"] == ref.k_m2
    assert b["source_kind"] == "network" and a["source_kind"] == "image"


def test_permeability_plain_text_output(image_file, capsys):
    assert main(["permeability", str(image_file), "--axis", "z"]) == 0
    out = capsys.readouterr().out
    assert "permeability_mD" in out and "axis" in out


# --- bad input: exit 2, one line, no traceback -------------------------------------------------------
def test_missing_file(tmp_path, capsys):
    _fails(capsys, ["extract", str(tmp_path / "nope.npy")], "nope.npy")
    _fails(capsys, ["permeability", str(tmp_path / "nope.npz")], "nope.npz")


def test_unknown_format(tmp_path, capsys):
    p = tmp_path / "img.xyz"
    p.write_text("1 2 3")
    _fails(capsys, ["extract", str(p)], "img.xyz")


def test_missing_voxel_size(tmp_path, capsys):
    p = tmp_path / "img.npy"
    np.save(p, lattice_image())
    _fails(capsys, ["extract", str(p)], "voxel")
    assert main(["extract", str(p), "--voxel-size", "1e-5", "--json"]) == 0
    assert _json(capsys)["voxel_size_m"] == 1e-5


@pytest.mark.parametrize("value", ["-1e-6", "0", "nan"])
def test_bad_voxel_size(tmp_path, capsys, value):
    p = tmp_path / "img.npy"
    np.save(p, lattice_image())
    _fails(capsys, ["extract", str(p), f"--voxel-size={value}"], "voxel-size")


def test_all_solid(tmp_path, capsys):
    p = tmp_path / "solid.npz"
    np.savez(p, image=np.zeros((10, 10, 10), np.uint8), voxel_size_m=VS)
    _fails(capsys, ["extract", str(p)], "no pore voxel")
    _fails(capsys, ["permeability", str(p)], "no pore voxel")


def test_no_percolating_path(tmp_path, capsys):
    img = np.zeros((20, 20, 20), np.uint8)
    img[5:9, :, 5:9] = 1  # a channel along y only
    p = tmp_path / "chan.npz"
    np.savez(p, image=img, voxel_size_m=VS)
    _fails(capsys, ["permeability", str(p), "--axis", "x"], "xmin", "axis")
    _fails(capsys, ["extract", str(p), "--axis", "z"], "zmin")


def test_image_options_with_network_file(image_file, tmp_path, capsys):
    net_path = tmp_path / "net.npz"
    assert main(["extract", str(image_file), "-o", str(net_path)]) == 0
    capsys.readouterr()
    _fails(capsys, ["permeability", str(net_path), "--voxel-size", "1e-6"], "--voxel-size", "network file")


def test_bad_output_paths(image_file, tmp_path, capsys):
    _fails(capsys, ["extract", str(image_file), "-o", str(tmp_path / "net.txt")], ".npz")
    _fails(capsys, ["extract", str(image_file), "--vtk", str(tmp_path / "no" / "n.vtp")], "does not exist")


def test_wrong_raw_size(tmp_path, capsys):
    p = tmp_path / "img.raw"
    lattice_image().tofile(p)
    _fails(capsys, ["extract", str(p), "--shape", "10", "10", "10", "--dtype", "uint8", "--voxel-size", "1e-5"],
           "img.raw")


def test_non_binary_without_threshold(tmp_path, capsys):
    img = lattice_image() * 200 + 17  # grey values {17, 217}, plus a third value
    img[0, 0, 0] = 100
    p = tmp_path / "grey.npz"
    np.savez(p, image=img, voxel_size_m=VS)
    _fails(capsys, ["extract", str(p)], "threshold")
    assert main(["extract", str(p), "--threshold", "150", "--pore-above", "--json"]) == 0
    assert _json(capsys)["n_pores"] == len(LATTICE.pore_radius)


def test_all_pore(tmp_path, capsys):
    p = tmp_path / "void.npz"
    np.savez(p, image=np.ones((10, 10, 10), np.uint8), voxel_size_m=VS)
    _fails(capsys, ["extract", str(p)], "pore")
    _fails(capsys, ["permeability", str(p)], "pore")


def test_unwritable_output_is_a_one_line_error(image_file, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    _fails(capsys, ["run", "-o", str(blocker)], "not a folder")
    (tmp_path / "ro").mkdir()
    (tmp_path / "ro" / "net.npz").mkdir()  # a folder where the file should go
    _fails(capsys, ["extract", str(image_file), "-o", str(tmp_path / "ro" / "net.npz")], "net.npz")
