"""Every bad file or option gets its one line, nonsense is refused or warned about (issue 13, s.5-7)."""

from __future__ import annotations

import errno
import io
import json

import numpy as np
import pytest

from porefsi.cli import main
from porefsi.network.lattice import lattice_network
from tests.test_reliability_run import CASE, one_line_error, porefsi

tifffile = pytest.importorskip("tifffile")
convert = pytest.importorskip("porefsi.network.convert")


def _image(shape=(24, 24, 24), seed=0) -> np.ndarray:
    return (np.random.default_rng(seed).random(shape) > 0.5).astype(np.uint8)


def _cli(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _one_line(code, err, *words):
    """Exit 2 and one error line (after any progress lines of the run)."""
    assert code == 2, err
    err = "".join(line for line in err.splitlines(keepends=True) if not line.startswith("porefsi run: step"))
    assert err.startswith("porefsi: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)


# -- section 5: headers that claim more memory than the machine has, damaged files ------------
def test_npy_and_mhd_headers_claiming_petabytes_are_refused_before_allocating(tmp_path):
    """Through the real CLI: numpy would try to allocate 1e15 bytes (or the OS kill the process)."""
    from numpy.lib import format as npf

    buf = io.BytesIO()
    npf.write_array_header_1_0(buf, {"descr": "|u1", "fortran_order": False, "shape": (100000, 100000, 100000)})
    (tmp_path / "huge.npy").write_bytes(buf.getvalue() + bytes(1000))
    (tmp_path / "huge.raw").write_bytes(bytes(1000))
    (tmp_path / "huge.mhd").write_text("NDims = 3\nDimSize = 100000 100000 100000\nElementType = MET_UCHAR\n"
                                       "ElementSpacing = 5 5 5\nCompressedData = True\nElementDataFile = huge.raw\n")
    for f in ("huge.npy", "huge.mhd"):
        r = porefsi("permeability", tmp_path / f, "--voxel-size", "5e-6")
        one_line_error(r, f, "needs about 1.78 PiB of memory", "available")


def test_truncated_and_object_npy_files(tmp_path, capsys):
    np.save(tmp_path / "full.npy", _image())
    (tmp_path / "cut.npy").write_bytes((tmp_path / "full.npy").read_bytes()[:3000])
    _one_line(*_cli(capsys, "extract", tmp_path / "cut.npy", "--voxel-size", "1e-6")[::2], "is truncated")
    np.save(tmp_path / "obj.npy", np.array([None] * 8, dtype=object).reshape(2, 2, 2), allow_pickle=True)
    _one_line(*_cli(capsys, "extract", tmp_path / "obj.npy", "--voxel-size", "1e-6")[::2], "Python objects")


@pytest.mark.parametrize("damage", ["ifd_offset", "truncated", "magic"])
def test_a_damaged_tiff_is_one_line(tmp_path, damage):
    f = tmp_path / "s.tif"
    tifffile.imwrite(f, _image().transpose(2, 1, 0))
    b = bytearray(f.read_bytes())
    if damage == "ifd_offset":
        b[4:8] = (10**9).to_bytes(4, "little")
    elif damage == "truncated":
        b = b[:300]
    else:
        b[:2] = b"XX"
    f.write_bytes(bytes(b))
    one_line_error(porefsi("extract", f, "--voxel-size", "1e-6"), str(f))


# -- section 7: TIFF stacks as scanners write them ----------------------------------------------
def test_a_stack_written_page_by_page_reads_like_one_written_at_once(tmp_path):
    from porefsi.image.io import read_image

    a = _image((20, 18, 16))
    tifffile.imwrite(tmp_path / "whole.tif", a.transpose(2, 1, 0))
    for k in range(a.shape[2]):  # one page (z slice, rows = y, columns = x) per call
        tifffile.imwrite(tmp_path / "pages.tif", a[:, :, k].T, append=k > 0)
    whole, pages = (read_image(tmp_path / n, voxel_size=1e-6) for n in ("whole.tif", "pages.tif"))
    np.testing.assert_array_equal(pages.phases, whole.phases)
    assert pages.shape == (20, 18, 16)


@pytest.mark.parametrize("kind", ["size", "dtype", "rgb", "rgb_stack"])
def test_mixed_pages_and_colour_images_are_refused_saying_what_was_found(tmp_path, capsys, kind):
    a = _image((12, 12, 5))
    f = tmp_path / f"{kind}.tif"
    if kind in ("size", "dtype"):
        for k in range(5):
            page = a[:, :, k]
            if k == 3:
                page = page[:8] if kind == "size" else page.astype(np.uint16)
            tifffile.imwrite(f, page, append=k > 0)
        words = ("page 0 is 12x12 uint8", "page 3 is " + ("8x12 uint8" if kind == "size" else "12x12 uint16"))
    else:
        shape = (12, 12, 3) if kind == "rgb" else (4, 12, 12, 3)
        tifffile.imwrite(f, np.zeros(shape, np.uint8), photometric="rgb")
        words = ("colour image", "3 samples per pixel")
    _one_line(*_cli(capsys, "extract", f, "--voxel-size", "1e-6")[::2], *words)


# -- section 5/6: options -------------------------------------------------------------------------
def test_voxel_size_out_of_range_is_refused_and_implausible_warned(tmp_path, capsys):
    np.save(tmp_path / "im.npy", _image())
    for vs in ("1e300", "5.345", "1e-300"):
        _one_line(*_cli(capsys, "extract", tmp_path / "im.npy", "--voxel-size", vs)[::2], "not the voxel size")
    code, _, err = _cli(capsys, "extract", tmp_path / "im.npy", "--voxel-size", "5e-3", "--keep-isolated",
                        "--min-radius", "1")
    assert "porefsi: warning: voxel_size (--voxel-size) = 0.005 m is outside 1 nm - 1 mm" in err, err
    assert err.count("\n") == 1 + (code != 0)


def test_a_rate_needing_more_than_100_MPa_is_warned_about(tmp_path, capsys):
    net = convert.save_network(lattice_network((6, 5, 3), 1e-4, np.random.default_rng(0)), tmp_path / "n.npz")
    code, out, err = _cli(capsys, "drainage", net, "--rate", "1e-3", "--t-end", "1e-9", "--snapshots", "0", "--json")
    assert code == 0, err
    assert "porefsi: warning: injecting 0.001 m^3/s through this network needs an inlet pressure of about" in err
    code, out, err = _cli(capsys, "drainage", net, "--rate", "1e-12", "--t-end", "1", "--snapshots", "0")
    assert code == 0 and "warning" not in err


def test_too_many_drainage_snapshots_need_force(tmp_path, capsys):
    net = convert.save_network(lattice_network((6, 5, 3), 1e-4, np.random.default_rng(0)), tmp_path / "n.npz")
    _one_line(*_cli(capsys, "drainage", net, "--snapshots", "100000", "-o", tmp_path / "o")[::2], "--force")
    assert not (tmp_path / "o").exists()


def test_an_unresolving_coarsening_is_refused_on_the_command_line_and_in_a_case(tmp_path, capsys):
    _one_line(*_cli(capsys, "solid", "--coarsen", "1000", "-o", tmp_path / "s")[::2], "coarsen = 1000",
              "1 block(s) across")
    _one_line(*_cli(capsys, "solid", "--coarsen", "20")[::2], "coarsen = 20", "turns most pores into solid")
    c = tmp_path / "c.toml"
    c.write_text(CASE.format(t_end=2.0, dt=1.0).replace("coarsen = 10", "coarsen = 1000"))
    _one_line(*_cli(capsys, "run", c, "-o", tmp_path / "r")[::2], "coarsen = 1000")
    assert not (tmp_path / "s").exists() and not (tmp_path / "r").exists()


# -- section 5: the output folder --------------------------------------------------------------
def test_a_read_only_output_folder_is_one_line(tmp_path, capsys, monkeypatch):
    """Sessions run as root, whom chmod does not stop: the read-only filesystem is simulated by an
    OSError(EROFS) from the lock file's creation (the first write into the folder)."""
    import porefsi.io.rundir as rundir

    real = rundir.os.open

    def refuse(path, *a, **k):
        if str(path).endswith(rundir.LOCK_NAME):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(rundir.os, "open", refuse)
    net = convert.save_network(lattice_network((6, 5, 3), 1e-4, np.random.default_rng(0)), tmp_path / "n.npz")
    _one_line(*_cli(capsys, "drainage", net, "-o", tmp_path / "ro")[::2], "Read-only file system", "another -o DIR")


def test_a_full_disk_mid_run_keeps_the_last_checkpoint(tmp_path, capsys, monkeypatch):
    """Simulated ENOSPC (see test_reliability_run for a real full tmpfs): the write of step 2's pore
    file fails; exit 2 with one line; the step-1 checkpoint is intact and --resume completes."""
    from porefsi.io import results

    c = tmp_path / "c.toml"
    c.write_text(CASE.format(t_end=3.0, dt=1.0))
    out = tmp_path / "out"
    real = results.atomic_write_bytes

    def fill(path, data):
        if "step_0002" in str(path):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(results, "atomic_write_bytes", fill)
    _one_line(*_cli(capsys, "run", c, "-o", out)[::2], "no space left", "step_0002", "--resume")
    monkeypatch.undo()
    assert results.load_checkpoint(out / "checkpoint.npz")[1]["step_index"] == 1
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "failed" and "No space left" in s["error"] and s["resume_command"]
    code, _, err = _cli(capsys, "run", c, "-o", out, "--resume", "--json")
    assert code == 0, err
    assert json.loads((out / "summary.json").read_text())["n_exchange_steps"] == 3


def test_random_bytes_npz_and_a_folder_as_case_file(tmp_path, capsys):
    """numpy's advice to pass allow_pickle never reaches a user; a folder is not 'not found'."""
    import os

    (tmp_path / "junk.npz").write_bytes(os.urandom(3000))
    code, _, err = _cli(capsys, "extract", tmp_path / "junk.npz", "--voxel-size", "1e-6")
    _one_line(code, err, "not numpy data")
    assert "allow_pickle" not in err
    (tmp_path / "c.toml").mkdir()
    _one_line(*_cli(capsys, "run", tmp_path / "c.toml")[::2], "is a folder")
