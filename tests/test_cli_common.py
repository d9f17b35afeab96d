"""Shared CLI helpers: argument types, image options, summaries."""

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from porefsi.cli._common import (
    add_image_args,
    emit,
    image_from_args,
    positive_float,
    positive_int,
    to_jsonable,
)
from porefsi.errors import InputError
from porefsi.image import load_sample


def _parser():
    p = argparse.ArgumentParser(prog="porefsi test")
    p.add_argument("image", nargs="?")
    add_image_args(p)
    return p


def _read(argv):
    args = _parser().parse_args(argv)
    return image_from_args(args, args.image)


def test_positive_float_and_int():
    assert positive_float("5.345e-6") == 5.345e-6
    assert positive_int("3") == 3
    for bad in ("0", "-1", "nan", "inf", "abc"):
        with pytest.raises(InputError):
            positive_float(bad)
    for bad in ("0", "-2", "1.5", "x"):
        with pytest.raises(InputError):
            positive_int(bad)


def test_bad_option_values_are_usage_errors_with_our_message(capsys):
    with pytest.raises(SystemExit) as info:
        _parser().parse_args(["--voxel-size=-1e-6"])
    assert info.value.code == 2
    assert "expected a positive finite number, got '-1e-6'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _parser().parse_args(["--threshold", "nan"])
    assert "finite number" in capsys.readouterr().err


def test_no_image_gives_the_builtin_sample():
    img = _read([])
    ref = load_sample()
    assert img.shape == ref.shape and img.voxel_size == ref.voxel_size
    np.testing.assert_array_equal(img.phases, ref.phases)
    assert _read(["--voxel-size", "1e-5"]).voxel_size == 1e-5


def test_segmentation_options_without_an_image_are_refused():
    with pytest.raises(InputError, match=r"--threshold --invert apply to an IMAGE file"):
        _read(["--threshold", "3", "--invert"])


def test_image_options_reach_the_reader(tmp_path, rng):
    grey = rng.integers(0, 200, size=(3, 4, 5)).astype(">u2")
    grey.ravel(order="F").tofile(tmp_path / "g.raw")
    img = _read([str(tmp_path / "g.raw"), "--shape", "3", "4", "5", "--dtype", ">u2", "--threshold", "99",
                 "--pore-above", "--voxel-size", "2e-6"])
    np.testing.assert_array_equal(img.phases, (grey > 99).astype(np.uint8))
    assert img.voxel_size == 2e-6
    lab = np.where(grey > 99, 7, 3).astype(np.int32)
    np.savez(tmp_path / "lab.npz", a=lab, b=lab)
    img = _read([str(tmp_path / "lab.npz"), "--key", "b", "--pore-value", "7", "--invert", "--voxel-size", "1e-6"])
    np.testing.assert_array_equal(img.phases, (grey <= 99).astype(np.uint8))


def test_missing_voxel_size_names_the_cli_flag(tmp_path, rng):
    np.save(tmp_path / "a.npy", (rng.random((3, 3, 3)) < 0.5).astype(np.uint8))
    with pytest.raises(InputError, match="--voxel-size M"):
        _read([str(tmp_path / "a.npy")])


def test_image_from_args_tolerates_parsers_without_every_option(tmp_path, rng):
    np.save(tmp_path / "a.npy", (rng.random((3, 3, 3)) < 0.5).astype(np.uint8))
    img = image_from_args(argparse.Namespace(voxel_size=1e-6), tmp_path / "a.npy")
    assert img.shape == (3, 3, 3)


def test_to_jsonable_and_emit(capsys):
    data = {"a": np.float64(1.5), "b": np.arange(3), "c": math.nan, "d": Path("x/y"), "e": (np.int32(2),),
            "f": {"g": np.bool_(True)}}
    assert to_jsonable(data) == {"a": 1.5, "b": [0, 1, 2], "c": None, "d": "x/y", "e": [2], "f": {"g": True}}
    emit(data, as_json=True)
    assert json.loads(capsys.readouterr().out) == to_jsonable(data)
    emit({"porosity": 0.188213541, "n": 3}, as_json=False)
    assert capsys.readouterr().out.splitlines() == ["porosity  0.188214", "n         3"]


def test_output_into_a_closed_pipe_is_not_an_error(tmp_path):
    """`porefsi ... --json | head -c 10`: the reader closes early; porefsi exits 0 without a traceback."""
    import subprocess
    import sys

    from porefsi.network.convert import save_network
    from porefsi.network.lattice import lattice_network

    net = save_network(lattice_network((4, 3, 3), 4e-5, np.random.default_rng(0)), tmp_path / "net.npz")
    proc = subprocess.Popen([sys.executable, "-m", "porefsi", "permeability", str(net), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # nobody reads the summary
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0 and "Traceback" not in err, err
