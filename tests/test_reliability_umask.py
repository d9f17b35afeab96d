"""Every output respects the user's umask (issue 13, section 8): the atomic writer used to leave 0600."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from porefsi.io import results


@pytest.fixture
def umask():
    old = os.umask(0o022)
    yield lambda m: os.umask(m)
    os.umask(old)


def _mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_atomic_writers_give_the_umask_permissions(tmp_path, umask, mask):
    from porefsi.io.network_vtk import write_network_vtp
    from porefsi.io.solid_vtk import write_solid_vtu
    from porefsi.network.lattice import lattice_network

    umask(mask)
    want = 0o666 & ~mask
    files = [
        results.atomic_write_bytes(tmp_path / "a.bin", b"x"),
        results.write_json(tmp_path / "s.json", {"a": 1}),
        results.write_csv(tmp_path / "t.csv", {"a": [1.0]}),
        results.write_npz(tmp_path / "p.npz", {"a": np.zeros(2)}),
        results.save_checkpoint(tmp_path / "c.npz", {"a": np.zeros(2)}, {"m": 1}),
        write_solid_vtu(tmp_path / "m.vtu", np.eye(4, 3), np.array([[0, 1, 2, 3]])),
        write_network_vtp(lattice_network((3, 3, 1), 1e-4, np.random.default_rng(0)), tmp_path / "n.vtp"),
    ]
    s = results.PvdSeries(tmp_path / "x.pvd")
    s.add(0.0, tmp_path / "m.vtu")
    files.append(s.path)
    for f in files:
        assert _mode(f) == want, (f.name, oct(_mode(f)))
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]


def test_file_mode_reads_the_umask_without_changing_it(umask):
    umask(0o027)
    assert results.file_mode() == 0o640
    assert os.umask(0o027) == 0o027
