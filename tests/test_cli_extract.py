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
    argv = [
        "extract",
        str(image_file),
        "--axis",
        "y",
        "-o",
        str(net_path),
        "--vtk",
        str(vtp),
        "--statoil",
        str(prefix),
        "--json",
    ]
    assert main(argv) == 0
    s = _json(capsys)
    for k in (
        "n_pores",
        "n_throats",
        "porosity",
        "voxel_size_m",
        "seconds",
        "mean_coordination",
        "removed_fraction",
        "network_file",
        "vtk_file",
    ):
        assert k in s, k
    img = lattice_image()
    assert s["voxel_size_m"] == VS and s["porosity"] == pytest.approx(LATTICE.porosity, rel=1e-15, abs=0)
    # One pore per sphere and one throat per cylinder of the construction.
    assert (s["n_pores"], s["n_throats"]) == (len(LATTICE.pore_radius), len(LATTICE.throat_conns))
    assert s["removed_fraction"] == 0.0  # the lattice is one percolating cluster
    # The same pipeline through the library gives the same network, and the file holds it.
    ext = extract_network(percolating_cluster(VoxelImage(img, VS), "y").image)
    net = load_network(net_path)
    assert (
        (s["n_pores"], s["n_throats"]) == (net.n_pores, net.n_throats) == (ext.network.n_pores, ext.network.n_throats)
    )
    np.testing.assert_array_equal(net.pore_coords, ext.network.pore_coords)
    assert s["mean_coordination"] == pytest.approx(2 * net.n_throats / net.n_pores, rel=1e-15, abs=0)
    _check_vtp(vtp, net)
    back = read_statoil(prefix, voxel_size=VS, axis="y")
    np.testing.assert_array_equal(back.throat_conns, net.throat_conns)


def _check_vtp(path, net):
    """The ``.vtp`` holds ``net``: one vertex per pore, one line per throat, joining the right pores."""
    pv = pytest.importorskip("pyvista")
    m = pv.read(path)
    # Layout of porefsi.io.network_vtk (tubes=True, the CLI's): the pore centres are the first Np
    # points, each throat line has two points of its own (carrying the throat radius for Tube).
    assert (m.n_verts, m.n_lines) == (net.n_pores, net.n_throats)
    assert m.n_points == net.n_pores + 2 * net.n_throats
    np.testing.assert_array_equal(m.points[: net.n_pores], net.pore_coords)
    lines = m.lines.reshape(-1, 3)[:, 1:]
    np.testing.assert_array_equal(m.point_data["pore_index"][lines], net.throat_conns)
    np.testing.assert_array_equal(m.point_data["radius"][: net.n_pores], net.pore_radius)


def test_vtk_written_by_extract_reads_back(image_file, tmp_path, capsys):
    vtp, net_path = tmp_path / "lattice.vtp", tmp_path / "lattice.npz"
    assert main(["extract", str(image_file), "--vtk", str(vtp), "-o", str(net_path), "--json"]) == 0
    s = _json(capsys)
    net = load_network(net_path)
    assert (s["n_pores"], s["n_throats"]) == (net.n_pores, net.n_throats) == (18, 33)
    assert s["vtk_file"] == str(vtp)
    _check_vtp(vtp, net)


# --- --keep-isolated ---------------------------------------------------------------------------------
CHANNEL_VOXELS = 24 * 6 * 6  # the percolating channel of the isolated_file image
BLOB_VOXELS = 8 * 5 * 5  # the closed pore body away from it


@pytest.fixture(scope="module")
def isolated_file(tmp_path_factory):
    img = np.zeros((24, 16, 16), np.uint8)
    img[:, 2:8, 2:8] = 1  # square channel along x: the one cluster that percolates
    img[8:16, 10:15, 10:15] = 1  # a closed pore body that touches neither the channel nor a face
    p = tmp_path_factory.mktemp("iso") / "iso.npz"
    np.savez(p, image=img, voxel_size_m=VS)
    return p


def test_keep_isolated_extracts_every_cluster(isolated_file, capsys):
    assert main(["extract", str(isolated_file), "--json"]) == 0
    a = _json(capsys)
    assert main(["extract", str(isolated_file), "--keep-isolated", "--json"]) == 0
    b = _json(capsys)
    # Default: the closed body is removed before extraction, and the summary says how much that was.
    assert a["removed_fraction"] == pytest.approx(BLOB_VOXELS / (CHANNEL_VOXELS + BLOB_VOXELS), rel=1e-15)
    assert a["connected_porosity"] == pytest.approx(CHANNEL_VOXELS / 24 / 16 / 16, rel=1e-15)
    # --keep-isolated: nothing removed, the body is one more pore with no throat.
    assert b["removed_fraction"] == 0.0 and b["connected_porosity"] == b["porosity"] == a["porosity"]
    assert (b["n_pores"], b["n_throats"]) == (a["n_pores"] + 1, a["n_throats"])
    assert b["n_isolated_pores"] == a["n_isolated_pores"] + 1
    # Same as the library on the unfiltered image.
    d = np.load(isolated_file)
    ext = extract_network(VoxelImage(d["image"], VS))
    assert (b["n_pores"], b["n_throats"]) == (ext.network.n_pores, ext.network.n_throats)


def test_keep_isolated_permeability_is_unchanged(isolated_file, capsys):
    assert main(["permeability", str(isolated_file), "--json"]) == 0
    a = _json(capsys)
    assert main(["permeability", str(isolated_file), "--keep-isolated", "--json"]) == 0
    b = _json(capsys)
    # The isolated pore carries no flow: left out of the solve, k identical.
    assert (a["n_excluded_pores"], b["n_excluded_pores"]) == (0, 1)
    assert b["n_pores"] == a["n_pores"] + 1 and b["n_pores_solved"] == a["n_pores_solved"]
    assert b["permeability_m2"] == pytest.approx(a["permeability_m2"], rel=1e-12, abs=0) and a["permeability_m2"] > 0


def test_keep_isolated_rejected_with_network_file(isolated_file, tmp_path, capsys):
    net_path = tmp_path / "net.npz"
    assert main(["extract", str(isolated_file), "-o", str(net_path)]) == 0
    capsys.readouterr()
    _fails(capsys, ["permeability", str(net_path), "--keep-isolated"], "--keep-isolated", "network file")


# --- extraction options (--min-radius, --extent, --merge-ratio) --------------------------------------
def test_extraction_defaults_in_help_match_extract_network(capsys):
    import inspect

    from porefsi.cli._extract import EXTRACT_DEFAULTS

    sig = inspect.signature(extract_network).parameters
    assert EXTRACT_DEFAULTS == {k: sig[k].default for k in EXTRACT_DEFAULTS}
    for cmd in ("extract", "permeability"):
        assert main([cmd, "--help"]) == 0
        out = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
        for opt, k in (("--min-radius", "min_radius"), ("--extent", "extent"), ("--merge-ratio", "merge_ratio")):
            assert opt in out, (cmd, opt)
            v = EXTRACT_DEFAULTS[k]
            assert (f"default {v:g}" if isinstance(v, float) else f"default {v}") in out, (cmd, opt)


def _thin_channel_file(tmp_path):
    """A channel 3 voxels wide and 1 thick along x: its largest ball radius is 1 voxel."""
    img = np.zeros((20, 7, 7), np.uint8)
    img[:, 2:5, 3] = 1
    p = tmp_path / "thin.npz"
    np.savez(p, image=img, voxel_size_m=VS)
    return p


def test_min_radius_option_applies_the_fix_the_error_names(tmp_path, capsys):
    p = _thin_channel_file(tmp_path)
    for cmd in ("extract", "permeability"):
        _fails(capsys, [cmd, str(p)], "no pore found", "--min-radius")
        assert main([cmd, str(p), "--min-radius", "1", "--json"]) == 0
        s = _json(capsys)
        assert s["min_radius_voxels"] == 1.0 and s["n_pores"] > 0
    assert s["permeability_m2"] > 0
    ref = extract_network(percolating_cluster(VoxelImage(np.load(p)["image"], VS), "x").image, min_radius=1)
    assert (s["n_pores"], s["n_throats"]) == (ref.network.n_pores, ref.network.n_throats)


def test_extent_option_applies_the_fix_the_error_names(tmp_path, capsys):
    # A straight tube of radius 4 voxels, 8 long: at the default reach its balls form one pore and
    # no throat; a shorter reach splits it into two pores joined by a throat.
    img = np.zeros((8, 13, 13), np.uint8)
    y, z = np.mgrid[:13, :13] - 6
    img[:, y**2 + z**2 <= 16] = 1
    p = tmp_path / "tube.npz"
    np.savez(p, image=img, voxel_size_m=VS)
    _fails(capsys, ["extract", str(p)], "no throat", "--extent")
    assert main(["extract", str(p), "--extent", "1", "--json"]) == 0
    s = _json(capsys)
    assert (s["n_pores"], s["n_throats"], s["extent_radii"]) == (2, 1, 1.0)
    assert main(["permeability", str(p), "--extent", "1", "--json"]) == 0
    assert _json(capsys)["permeability_m2"] > 0


def test_extraction_options_reach_extract_network(capsys):
    """All three options on the built-in sample: the CLI network is the library's with the same values."""
    from porefsi.image import load_sample

    kw = {"min_radius": 1.5, "extent": 8.0, "merge_ratio": 0.5}
    argv = ["--min-radius", "1.5", "--extent", "8", "--merge-ratio", "0.5", "--json"]
    ref = extract_network(percolating_cluster(load_sample(), "x").image, **kw).network
    default = extract_network(percolating_cluster(load_sample(), "x").image).network
    assert ref.n_pores != default.n_pores  # the options change the answer, so the test can see them
    assert main(["extract", *argv]) == 0
    s = _json(capsys)
    assert (s["n_pores"], s["n_throats"]) == (ref.n_pores, ref.n_throats)
    assert (s["min_radius_voxels"], s["extent_radii"], s["merge_ratio"]) == (1.5, 8.0, 0.5)
    assert s["min_radius_rule"] == "voxels"
    assert main(["extract", "--min-radius", "auto", "--json"]) == 0
    a = _json(capsys)
    assert a["min_radius_rule"] == "auto" and a["n_pores"] == default.n_pores  # the sample's own floor is 2 voxels
    assert main(["permeability", *argv]) == 0
    k = _json(capsys)
    assert k["n_pores"] == ref.n_pores
    assert k["permeability_m2"] == absolute_permeability(ref, "x").k_m2


@pytest.mark.parametrize(
    "opt,value,words",
    [
        ("--min-radius", "0.5", (">= 1", "'auto'")),
        ("--min-radius", "nan", ("finite", "'auto'")),
        ("--min-radius", "automatic", ("'automatic'", "'auto'")),
        ("--extent", "0", ("positive finite",)),
        ("--extent", "0.9", (">= 1",)),
        ("--merge-ratio", "1.5", ("(0, 1]",)),
        ("--merge-ratio", "-0.1", ("positive finite",)),
        ("--merge-ratio", "abc", ("expected a number",)),
    ],
)
def test_bad_extraction_options(image_file, capsys, opt, value, words):
    for cmd in ("extract", "permeability"):
        _fails(capsys, [cmd, str(image_file), f"{opt}={value}"], opt, *words)


def test_extraction_options_rejected_with_network_file(image_file, tmp_path, capsys):
    net_path = tmp_path / "net.npz"
    assert main(["extract", str(image_file), "-o", str(net_path)]) == 0
    capsys.readouterr()
    for opt in ("--min-radius", "--extent", "--merge-ratio"):
        _fails(capsys, ["permeability", str(net_path), opt, "1"], opt, "network file")


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
    _fails(capsys, ["extract", str(p), "--axis", "z"], "zmin", "--axis", "--keep-isolated")
    # The fix the message names works from the CLI: the channel is extracted without the filter.
    assert main(["extract", str(p), "--axis", "z", "--keep-isolated", "--json"]) == 0
    s = _json(capsys)
    assert s["removed_fraction"] == 0.0 and s["n_pores"] > 0


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
    _fails(
        capsys, ["extract", str(p), "--shape", "10", "10", "10", "--dtype", "uint8", "--voxel-size", "1e-5"], "img.raw"
    )


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
