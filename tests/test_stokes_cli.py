"""``porefsi permeability --method voxel``, called through ``main(argv)``."""

import json

import numpy as np
import pytest

from porefsi.cli import main
from porefsi.image import VoxelImage, downsample
from porefsi.stokes import voxel_permeability

VS = 2e-6


def _image():
    rng = np.random.default_rng(5)
    from scipy import ndimage

    field = ndimage.gaussian_filter(rng.standard_normal((16, 14, 12)), 1.3)
    return (field < np.quantile(field, 0.5)).astype(np.uint8)


@pytest.fixture(scope="module")
def image_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("img") / "rock.npz"
    np.savez(p, image=_image(), voxel_size_m=VS)
    return p


def _json(capsys):
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1, out
    return json.loads(out[0])


def _fails(capsys, argv, *words):
    code = main(argv)
    cap = capsys.readouterr()
    assert code == 2 and "Traceback" not in cap.err and cap.out == "", (code, cap)
    errs = [ln for ln in cap.err.splitlines() if "error:" in ln]
    assert len(errs) == 1, cap.err
    for w in words:
        assert w.lower() in errs[0].lower(), (w, errs[0])


@pytest.mark.parametrize("axis", ["x", "z"])
def test_voxel_method_matches_the_api(image_file, capsys, axis):
    assert main(["permeability", str(image_file), "--method", "voxel", "--axis", axis, "--json"]) == 0
    s = _json(capsys)
    ref = voxel_permeability(VoxelImage(_image(), VS), axis)
    assert s["method"] == "voxel" and s["axis"] == axis and s["boundary"] == "pressure" and s["buffer"] == 2
    assert s["permeability_m2"] == pytest.approx(ref.k_m2, rel=1e-5)
    assert s["permeability_mD"] == pytest.approx(s["permeability_m2"] / 9.869233e-16, rel=1e-12)
    for k in ("iterations", "residual", "flux_spread", "memory_estimate_bytes", "seconds", "cpu_seconds",
              "n_unknowns", "connected_porosity"):
        assert k in s, k
    assert s["flux_spread"] < 1e-3 and s["iterations"] > 0


def test_voxel_method_coarsen_and_periodic(image_file, capsys):
    argv = ["permeability", str(image_file), "--method", "voxel", "--coarsen", "2", "--boundary", "periodic",
            "--rtol", "1e-8", "--json"]
    assert main(argv) == 0
    s = _json(capsys)
    ref = voxel_permeability(downsample(VoxelImage(_image(), VS), 2), "x", boundary="periodic", mirror=True,
                             rtol=1e-8)
    assert s["solved_shape"] == [8, 7, 6] and s["solved_voxel_size_m"] == 2 * VS
    assert s["permeability_m2"] == pytest.approx(ref.k_m2, rel=1e-6)


def test_network_method_is_the_default(image_file, capsys):
    assert main(["permeability", str(image_file), "--json"]) == 0
    assert _json(capsys)["method"] == "network"


def test_voxel_method_errors(image_file, tmp_path, capsys):
    _fails(capsys, ["permeability", str(image_file), "--buffer", "3"], "--buffer", "--method voxel")
    _fails(capsys, ["permeability", str(image_file), "--method", "voxel", "--min-radius", "1"], "--min-radius")
    _fails(capsys, ["permeability", str(image_file), "--method", "voxel", "--rtol", "2"], "--rtol")
    _fails(capsys, ["permeability", str(image_file), "--method", "voxel", "--buffer", "-1"], "--buffer")
    _fails(capsys, ["permeability", str(image_file), "--method", "lbm"], "--method")
    blocked = np.ones((6, 4, 4), np.uint8)
    blocked[3] = 0
    p = tmp_path / "blocked.npz"
    np.savez(p, image=blocked, voxel_size_m=VS)
    _fails(capsys, ["permeability", str(p), "--method", "voxel"], "no pore path")
    _fails(capsys, ["permeability", str(image_file), "--method", "voxel", "--maxiter", "2"], "did not converge")


def test_voxel_method_refuses_a_network_file(image_file, tmp_path, capsys):
    net = tmp_path / "net.npz"
    assert main(["extract", str(image_file), "--min-radius", "1", "-o", str(net)]) == 0
    capsys.readouterr()
    _fails(capsys, ["permeability", str(net), "--method", "voxel"], "network file", "image")


def test_voxel_method_wall_closure(image_file, capsys):
    """--wall picks the tangential closure; each matches the API, and they differ on this image."""
    ks = {}
    for wall in ("ghost", "channel"):
        assert main(["permeability", str(image_file), "--method", "voxel", "--wall", wall, "--json"]) == 0
        s = _json(capsys)
        assert s["wall"] == wall
        ks[wall] = s["permeability_m2"]
        assert ks[wall] == pytest.approx(voxel_permeability(VoxelImage(_image(), VS), "x", wall=wall).k_m2, rel=1e-5)
    assert ks["channel"] < 0.95 * ks["ghost"]
    _fails(capsys, ["permeability", str(image_file), "--wall", "ghost"], "--wall", "--method voxel")
