"""Readers, writers and segmentation of porefsi.image.io.

Every reader is checked on a file whose voxels we wrote ourselves (bit-exact), every writer by a
round trip, and every bad input by its typed error and a message that names the fix.
"""

import gzip
from pathlib import Path

import numpy as np
import pytest
import tifffile
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from porefsi.errors import InputError
from porefsi.image import SAMPLES, RawLayout, VoxelImage, load_sample, read_image, segment, write_image


def _binary(rng, shape=(5, 6, 7), p=0.4):
    a = (rng.random(shape) < p).astype(np.uint8)
    a[0, 0, 0], a[-1, -1, -1] = 1, 0  # never all-pore / all-solid
    return a


def _frozen_copy(img: VoxelImage):
    return img.phases.copy(), img.voxel_size, img.origin.copy()


def _same(img: VoxelImage, ref) -> None:
    phases, vs, origin = ref
    assert img.phases.dtype == np.uint8
    np.testing.assert_array_equal(img.phases, phases)
    assert img.voxel_size == vs
    np.testing.assert_array_equal(img.origin, origin)


def _mhd(path: Path, data_file: str, dims, etype="MET_UCHAR", spacing="5.345 5.345 5.345", extra="", tail=""):
    path.write_text(
        "ObjectType = Image\nNDims = 3\n"
        f"DimSize = {' '.join(map(str, dims))}\nElementType = {etype}\n"
        f"ElementSpacing = {spacing}\n{extra}ElementDataFile = {data_file}\n{tail}"
    )
    return path


# ------------------------------------------------------------------------------------------
# segmentation conventions
# ------------------------------------------------------------------------------------------
def test_segment_bool_and_01_are_taken_as_is(rng):
    a = _binary(rng)
    np.testing.assert_array_equal(segment(a.astype(bool)), a)
    np.testing.assert_array_equal(segment(a), a)
    np.testing.assert_array_equal(segment(a.astype(np.float32)), a)
    np.testing.assert_array_equal(segment(a, invert=True), 1 - a)


def test_segment_0_255_with_invert_is_icl_convention(rng):
    a = _binary(rng)
    icl = np.where(a == 1, 0, 255).astype(np.uint8)  # berea.tif: 0 = pore, 255 = solid
    np.testing.assert_array_equal(segment(icl, invert=True), a)
    np.testing.assert_array_equal(segment(icl), 1 - a)  # default: nonzero = pore


def test_segment_grey_threshold_and_pore_above(rng):
    grey = rng.integers(0, 256, size=(6, 6, 6)).astype(np.uint16)
    np.testing.assert_array_equal(segment(grey, threshold=100), (grey <= 100).astype(np.uint8))
    np.testing.assert_array_equal(segment(grey, threshold=100, pore_above=True), (grey > 100).astype(np.uint8))
    # the threshold value itself is pore (<=) without pore_above, solid with it
    edge = np.array([[[99, 100, 101]]])
    assert segment(edge, threshold=100).tolist() == [[[1, 1, 0]]]
    assert segment(edge, threshold=100, pore_above=True).tolist() == [[[0, 0, 1]]]


def test_segment_labelled_pore_value():
    lab = np.array([[[0, 1, 2], [2, 3, 2]]], dtype=np.int16)
    assert segment(lab, pore_value=2).tolist() == [[[0, 0, 1], [1, 0, 1]]]
    assert segment(lab, pore_value=2, invert=True).tolist() == [[[1, 1, 0], [0, 1, 0]]]


def test_segment_never_modifies_or_aliases_its_input(rng):
    for a in (_binary(rng).astype(bool), _binary(rng), rng.random((4, 4, 4))):
        before = a.copy()
        out = segment(a, threshold=0.5) if a.dtype.kind == "f" else segment(a)
        np.testing.assert_array_equal(a, before)
        assert not np.shares_memory(out, a)
        out[...] = 0  # writing the result must not reach the input
        np.testing.assert_array_equal(a, before)


@pytest.mark.parametrize(
    ("array", "kwargs", "fragments"),
    [
        (np.array([[[0, 1, 2]]]), {}, ["more than two distinct values (0, 1, 2)", "threshold=", "pore_value="]),
        (np.array([[[1, 2, 2]]]), {}, ["two nonzero distinct values (1, 2)", "--threshold"]),
        (np.array([[[0.0, np.nan, 1.0]]]), {}, ["NaN"]),
        (np.zeros((2, 2, 2)), {}, ["no pore voxel", "invert"]),
        (np.full((2, 2, 2), 255), {}, ["every voxel is pore", "invert"]),
        (np.array([[[0, 1]]]), {"invert": True, "threshold": 5}, ["no pore voxel"]),
        (np.array([[[0, 1, 2]]]), {"pore_value": 7}, ["pore_value=7 does not occur", "0, 1, 2"]),
        (np.array([[[0, 1, 2]]]), {"pore_value": 1, "threshold": 1}, ["pass only one"]),
        (np.array([[[0, 1]]]), {"pore_above": True}, ["pore_above only applies with a threshold"]),
        (np.array([[[0, 1, 2]]]), {"threshold": float("nan")}, ["threshold is NaN"]),
        (np.array([[["a", "b"]]]), {}, ["not numeric"]),
    ],
)
def test_segment_bad_input_names_problem_and_fix(array, kwargs, fragments):
    with pytest.raises(InputError) as info:
        segment(array, **kwargs)
    for frag in fragments:
        assert frag in str(info.value)


def test_segment_lists_only_the_first_distinct_values():
    with pytest.raises(InputError, match=r"\(0, 1, 2, 3, 4, 5, 6, 7, \.\.\.\)"):
        segment(np.arange(64, dtype=np.uint8).reshape(4, 4, 4))


# ------------------------------------------------------------------------------------------
# round trips of the writers
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["img.npz", "img.mhd", "img.raw"])
def test_write_read_round_trip_is_exact_and_leaves_input_alone(tmp_path, rng, name):
    img = VoxelImage(_binary(rng, (7, 5, 3)), 5.345e-6, origin=[180 * 5.345e-6, -0.1, 1 / 3])
    ref = _frozen_copy(img)
    out = write_image(img, tmp_path / name)
    _same(img, ref)  # writer did not touch its input
    _same(read_image(out), ref)
    assert out.suffix in (".npz", ".mhd")


def test_mhd_writer_layout_is_x_fastest_with_metre_units(tmp_path):
    a = np.zeros((3, 2, 2), np.uint8)
    a[1, 0, 0] = 1  # second voxel along x: second byte of an x-fastest file
    a[0, 1, 1] = 1  # (0, 1, 1): byte 0 + 1*3 + 1*3*2 = 9
    hdr = write_image(VoxelImage(a, 2.5e-6), tmp_path / "lay.mhd")
    raw = np.fromfile(tmp_path / "lay.raw", dtype=np.uint8)
    assert np.flatnonzero(raw).tolist() == [1, 9]
    text = hdr.read_text()
    assert "DimSize = 3 2 2" in text and "Unit = 1\n" in text and "ElementSpacing = 2.5e-06" in text
    assert "Offset = 1.25e-06 1.25e-06 1.25e-06" in text  # centre of the first voxel (ITK, VTK)
    assert text.rstrip().endswith("ElementDataFile = lay.raw")  # MetaImage: data file comes last


finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(
    phases=arrays(np.uint8, st.tuples(*[st.integers(1, 5)] * 3), elements=st.integers(0, 1)),
    voxel_size=st.floats(min_value=1e-9, max_value=1e-2, allow_nan=False, allow_infinity=False),
    origin=st.tuples(finite, finite, finite),
    suffix=st.sampled_from([".npz", ".mhd"]),
)
def test_round_trip_property(tmp_path_factory, phases, voxel_size, origin, suffix):
    """Any image, voxel size and origin come back bit for bit (the writers lose nothing)."""
    img = VoxelImage(phases, voxel_size, origin)
    path = tmp_path_factory.mktemp("rt") / f"img{suffix}"
    ref = _frozen_copy(img)
    if phases.min() == phases.max():  # all pore or all solid: written fine, refused on reading
        write_image(img, path)
        with pytest.raises(InputError, match="segmentation"):
            read_image(path)
        return
    _same(read_image(write_image(img, path)), ref)


def test_write_image_rejects_unknown_suffix_and_non_images(tmp_path, rng):
    img = VoxelImage(_binary(rng), 1e-6)
    with pytest.raises(InputError, match=r"\.npz, \.mhd"):
        write_image(img, tmp_path / "a.tif")
    with pytest.raises(InputError, match="VoxelImage"):
        write_image(np.zeros((2, 2, 2)), tmp_path / "a.npz")


# ------------------------------------------------------------------------------------------
# readers of files written by other tools
# ------------------------------------------------------------------------------------------
def test_npy_needs_voxel_size(tmp_path, rng):
    a = _binary(rng)
    np.save(tmp_path / "a.npy", a)
    with pytest.raises(InputError, match=r"voxel size unknown.*voxel_size=.*--voxel-size"):
        read_image(tmp_path / "a.npy")
    img = read_image(tmp_path / "a.npy", voxel_size=3e-6)
    np.testing.assert_array_equal(img.phases, a)
    assert img.voxel_size == 3e-6 and img.origin.tolist() == [0, 0, 0]


def test_npz_key_detection_voxel_size_and_override(tmp_path, rng):
    a = _binary(rng)
    np.savez(tmp_path / "k.npz", phases=a, voxel_size=np.float64(2e-6))
    img = read_image(tmp_path / "k.npz")
    np.testing.assert_array_equal(img.phases, a)
    assert img.voxel_size == 2e-6
    assert read_image(tmp_path / "k.npz", voxel_size=7e-6).voxel_size == 7e-6  # explicit wins
    # the only 3-D array among others is found; key= picks one explicitly
    np.savez(tmp_path / "only.npz", labels=np.arange(3), vol=a)
    np.testing.assert_array_equal(read_image(tmp_path / "only.npz", voxel_size=1e-6).phases, a)
    np.savez(tmp_path / "two.npz", a=a, b=1 - a)
    np.testing.assert_array_equal(read_image(tmp_path / "two.npz", voxel_size=1e-6, key="b").phases, 1 - a)
    with pytest.raises(InputError, match=r"key=.*--key"):
        read_image(tmp_path / "two.npz", voxel_size=1e-6)
    with pytest.raises(InputError, match=r"no array 'c'; its keys are \['a', 'b'\]"):
        read_image(tmp_path / "two.npz", voxel_size=1e-6, key="c")


def test_npz_network_file_is_named_as_such(tmp_path):
    np.savez(tmp_path / "net.npz", **{"pore.coords": np.zeros((2, 3)), "throat.conns": np.array([[0, 1]])})
    with pytest.raises(InputError, match="looks like a pore-network file"):
        read_image(tmp_path / "net.npz")


def test_raw_with_mhd_header_uint16_big_endian_micrometres(tmp_path, rng):
    grey = rng.integers(0, 4000, size=(4, 3, 5)).astype(np.uint16)
    grey.ravel(order="F").astype(">u2").tofile(tmp_path / "g.raw")  # x fastest, MSB first
    before = (tmp_path / "g.raw").read_bytes()
    _mhd(tmp_path / "g.mhd", "g.raw", grey.shape, "MET_USHORT", extra="BinaryDataByteOrderMSB = True\n")
    for path in (tmp_path / "g.mhd", tmp_path / "g.raw"):  # header found next to the .raw
        img = read_image(path, threshold=1500)
        np.testing.assert_array_equal(img.phases, (grey <= 1500).astype(np.uint8))
        assert img.voxel_size == 5.345e-6  # 5.345 > 0.02: micrometres (pnextract's rule)
    assert (tmp_path / "g.raw").read_bytes() == before


def test_mhd_pnextract_style_header(tmp_path, rng):
    """ICL/pnextract headers: ElementSize, gzipped data, Unit after ElementDataFile, comments."""
    a = _binary(rng, (4, 4, 4))
    (tmp_path / "b.raw.gz").write_bytes(gzip.compress(np.where(a == 1, 0, 255).astype(np.uint8).tobytes("F")))
    (tmp_path / "b.mhd").write_text(
        "ObjectType =  Image\nNDims =       3\nElementType = MET_UCHAR\n\nDimSize = 4 4 4\n"
        "ElementSize = 3.2 3.2 3.2\nOffset = 0 0 0\n\nElementDataFile = b.raw.gz\n\n"
        "Unit = 1e-3\nOffset = 0 0 0\n#threshold 0 128\n'comment'\n______ free text\ncropD 0 0 0 2 2 2\n"
    )
    img = read_image(tmp_path / "b.mhd", invert=True)
    np.testing.assert_array_equal(img.phases, a)
    assert img.voxel_size == 3.2e-3  # Unit = 1e-3 m per unit overrides the auto rule
    np.testing.assert_allclose(img.origin, -1.6e-3)  # Offset is the first voxel's centre


def test_mhd_pnextract_commands_are_refused_not_ignored(tmp_path, rng):
    a = _binary(rng, (3, 3, 3))
    a.tofile(tmp_path / "c.raw")
    _mhd(tmp_path / "c.mhd", "c.raw", a.shape, tail="\ncropD 0 0 0 2 2 2\n")
    with pytest.raises(InputError, match=r"cropD 0 0 0 2 2 2.*comment the lines out"):
        read_image(tmp_path / "c.mhd")


def test_mhd_unit_ambiguous_band_and_explicit_units(tmp_path, rng):
    a = _binary(rng, (3, 3, 3))
    a.ravel(order="F").tofile(tmp_path / "u.raw")
    _mhd(tmp_path / "u.mhd", "u.raw", a.shape, spacing="0.005345 0.005345 0.005345")
    with pytest.raises(InputError, match=r"no unit.*mhd_unit='m' or 'mm'.*--mhd-unit"):
        read_image(tmp_path / "u.mhd")
    assert read_image(tmp_path / "u.mhd", mhd_unit="mm").voxel_size == 5.345e-6
    assert read_image(tmp_path / "u.mhd", mhd_unit="m").voxel_size == 0.005345
    _mhd(tmp_path / "m.mhd", "u.raw", a.shape, spacing="2e-6 2e-6 2e-6")
    assert read_image(tmp_path / "m.mhd").voxel_size == 2e-6  # <= 1e-4: metres
    assert read_image(tmp_path / "m.mhd", voxel_size=1e-5).voxel_size == 1e-5
    with pytest.raises(InputError, match="unknown mhd_unit 'furlong'"):
        read_image(tmp_path / "m.mhd", mhd_unit="furlong")


def test_mhd_local_data_and_header_size(tmp_path, rng):
    a = _binary(rng, (2, 3, 4))
    head = b"ObjectType = Image\nNDims = 3\nDimSize = 2 3 4\nElementType = MET_UCHAR\n" \
           b"ElementSpacing = 1e-6 1e-6 1e-6\nElementDataFile = LOCAL\n"
    (tmp_path / "l.mhd").write_bytes(head + a.tobytes("F"))
    np.testing.assert_array_equal(read_image(tmp_path / "l.mhd").phases, a)
    (tmp_path / "h.raw").write_bytes(b"JUNKJUNK" + a.tobytes("F"))
    for hsize in ("8", "-1"):
        _mhd(tmp_path / "h.mhd", "h.raw", a.shape, spacing="1e-6 1e-6 1e-6", extra=f"HeaderSize = {hsize}\n")
        np.testing.assert_array_equal(read_image(tmp_path / "h.mhd").phases, a)


@pytest.mark.parametrize(
    ("header_kw", "fragment"),
    [
        ({"spacing": "1 1 2"}, "not cubic"),
        ({"etype": "MET_STRANGE"}, "unsupported ElementType"),
        ({"data_file": "nothere.raw"}, "does not exist"),
        ({"dims": (3, 3, 4)}, "holds 27 bytes of voxel data but shape (3, 3, 4)"),
        ({"dims": (3, 3)}, "DimSize must have 3 values"),
    ],
)
def test_mhd_bad_headers(tmp_path, rng, header_kw, fragment):
    a = _binary(rng, (3, 3, 3))
    a.ravel(order="F").tofile(tmp_path / "d.raw")
    kw = {"data_file": "d.raw", "dims": a.shape, **header_kw}
    _mhd(tmp_path / "d.mhd", kw.pop("data_file"), kw.pop("dims"), **kw)
    with pytest.raises(InputError) as info:
        read_image(tmp_path / "d.mhd")
    assert fragment in str(info.value)


@pytest.mark.parametrize(("dtype", "order"), [("uint8", "F"), ("<u2", "F"), (">u2", "F"), (">u2", "C"), ("<f4", "F")])
def test_raw_explicit_shape_and_dtype(tmp_path, rng, dtype, order):
    grey = rng.integers(0, 250, size=(3, 4, 5)).astype(dtype)
    np.ravel(grey, order=order).tofile(tmp_path / "r.bin")
    img = read_image(tmp_path / "r.bin", raw=RawLayout((3, 4, 5), dtype, order), threshold=120, voxel_size=1e-6)
    np.testing.assert_array_equal(img.phases, (grey <= 120).astype(np.uint8))


def test_raw_wrong_size_and_missing_shape(tmp_path):
    np.zeros(100, np.uint16).tofile(tmp_path / "w.raw")  # 200 bytes
    with pytest.raises(InputError, match=r"holds 200 bytes .* needs 120"):
        read_image(tmp_path / "w.raw", raw=RawLayout((3, 4, 5), "uint16"), voxel_size=1e-6)
    with pytest.raises(InputError, match=r"raw=RawLayout\(shape=\(nx, ny, nz\), dtype=\.\.\.\).*--shape NX NY NZ"):
        read_image(tmp_path / "w.raw", voxel_size=1e-6)
    with pytest.raises(InputError, match="unknown dtype"):
        read_image(tmp_path / "w.raw", raw=RawLayout((10, 10, 1), "uint77"), voxel_size=1e-6)
    with pytest.raises(InputError, match="3 positive integers"):
        read_image(tmp_path / "w.raw", raw=RawLayout((200,), "uint8"), voxel_size=1e-6)


def test_tiff_stack_axes_and_no_resolution(tmp_path, rng):
    vol = _binary(rng, (4, 5, 6))  # (x, y, z)
    pages = vol.transpose(2, 1, 0)  # TIFF stack: one page per z, rows = y, columns = x
    tifffile.imwrite(tmp_path / "s.tif", pages, photometric="minisblack")
    before = (tmp_path / "s.tif").read_bytes()
    with pytest.raises(InputError, match="voxel size unknown"):
        read_image(tmp_path / "s.tif")
    img = read_image(tmp_path / "s.tif", voxel_size=4e-6)
    np.testing.assert_array_equal(img.phases, vol)
    assert (tmp_path / "s.tif").read_bytes() == before
    # the same volume as raw + mhd reads identically (x fastest on disk in both)
    write_image(img, tmp_path / "s.mhd")
    np.testing.assert_array_equal(read_image(tmp_path / "s.mhd").phases, img.phases)


def test_tiff_resolution_tags(tmp_path, rng):
    vol = _binary(rng, (4, 5, 6))
    pages = vol.transpose(2, 1, 0)
    tifffile.imwrite(tmp_path / "ij.tif", pages * 255, imagej=True, resolution=(1 / 2.5, 1 / 2.5),
                     metadata={"spacing": 2.5, "unit": "um", "axes": "ZYX"})
    img = read_image(tmp_path / "ij.tif")
    np.testing.assert_array_equal(img.phases, vol)
    assert img.voxel_size == pytest.approx(2.5e-6, rel=1e-12)
    tifffile.imwrite(tmp_path / "cm.tif", pages, photometric="minisblack",
                     resolution=(1e4 / 3.0, 1e4 / 3.0), resolutionunit="CENTIMETER")
    assert read_image(tmp_path / "cm.tif").voxel_size == pytest.approx(3e-6, rel=1e-12)
    tifffile.imwrite(tmp_path / "dpi.tif", pages, photometric="minisblack", resolution=(72, 72),
                     resolutionunit="INCH")  # an editor's default, says nothing about the scan
    with pytest.raises(InputError, match="voxel size unknown"):
        read_image(tmp_path / "dpi.tif")
    tifffile.imwrite(tmp_path / "aniso.tif", pages, imagej=True, resolution=(1 / 2.5, 1 / 2.5),
                     metadata={"spacing": 5.0, "unit": "um", "axes": "ZYX"})
    with pytest.raises(InputError, match="not cubic"):
        read_image(tmp_path / "aniso.tif")
    assert read_image(tmp_path / "aniso.tif", voxel_size=1e-6).voxel_size == 1e-6


def test_tiff_single_page_suggests_adding_an_axis(tmp_path):
    tifffile.imwrite(tmp_path / "one.tif", np.eye(4, dtype=np.uint8), photometric="minisblack")
    with pytest.raises(InputError, match="add an axis"):
        read_image(tmp_path / "one.tif", voxel_size=1e-6)


@pytest.mark.parametrize(
    ("make", "fragment"),
    [
        (lambda p: p / "absent.npy", "does not exist"),
        (lambda p: p, "is a directory"),
        (lambda p: (p / "x.png").write_bytes(b"x") and p / "x.png", "unknown image format '.png'"),
        (lambda p: np.save(p / "flat.npy", np.ones((3, 3))) or p / "flat.npy", "2-D array"),
        (lambda p: np.save(p / "four.npy", np.ones((2, 2, 2, 2))) or p / "four.npy", "4-D array"),
        (lambda p: (p / "bad.npz").write_bytes(b"not a zip") and p / "bad.npz", "cannot read"),
        (lambda p: (p / "bad.tif").write_bytes(b"not a tiff") and p / "bad.tif", "not a readable TIFF"),
    ],
)
def test_bad_files(tmp_path, make, fragment):
    with pytest.raises(InputError) as info:
        read_image(make(tmp_path), voxel_size=1e-6)
    assert fragment in str(info.value)


def test_unknown_format_lists_supported(tmp_path):
    (tmp_path / "x.vtk").write_text("x")
    with pytest.raises(InputError, match=r"supported: \.npy, \.npz, \.mhd, \.raw"):
        read_image(tmp_path / "x.vtk")


def test_voxel_size_must_be_positive(tmp_path, rng):
    np.save(tmp_path / "a.npy", _binary(rng))
    for bad in (0.0, -1e-6, float("nan"), float("inf")):
        with pytest.raises(InputError, match="positive length in metres"):
            read_image(tmp_path / "a.npy", voxel_size=bad)


@pytest.mark.parametrize("bad", ["abc", "", [1e-6, 2e-6], object()], ids=["abc", "empty", "list", "object"])
@pytest.mark.parametrize("name", ["a.npy", "a.npz", "a.mhd", "a.tif"])
def test_non_numeric_voxel_size_is_an_input_error_for_every_reader(tmp_path, rng, name, bad):
    # Before the fix, float("abc") escaped as a bare ValueError (.npy), or, for .mhd, was caught by the
    # reader and reported as an unreadable file. The check now runs before the file is opened.
    img = VoxelImage(_binary(rng), 2e-6)
    path = tmp_path / name
    if name == "a.npy":
        np.save(path, img.phases)
    elif name == "a.tif":
        tifffile.imwrite(path, img.phases.transpose(2, 1, 0))
    else:
        path = write_image(img, path)
    with pytest.raises(InputError, match="voxel_size must be a positive length in metres") as err:
        read_image(path, voxel_size=bad)
    assert "cannot read" not in str(err.value) and "--voxel-size" in str(err.value)
    assert read_image(path, voxel_size="3e-6").voxel_size == 3e-6  # a numeric string is a number


@pytest.mark.parametrize("bad", ["abc", None, [1e-6]])
def test_voxel_image_rejects_non_numeric_voxel_size(rng, bad):
    with pytest.raises(InputError, match="voxel size must be a positive length in metres"):
        VoxelImage(_binary(rng), bad)


# ------------------------------------------------------------------------------------------
# built-in sample
# ------------------------------------------------------------------------------------------
def test_builtin_sample_matches_its_documentation():
    """Figures stated in porefsi/data/ATTRIBUTION.md (and the seed paper's table 2)."""
    img = load_sample()
    assert img.shape == (120, 120, 120)
    assert img.voxel_size == 5.345e-6
    assert img.porosity == pytest.approx(0.18821, abs=1e-5)
    assert img.origin.tolist() == [0.0, 0.0, 0.0]
    assert "berea120" in SAMPLES and "MIT" in SAMPLES["berea120"][1]


def test_unknown_sample_lists_names():
    with pytest.raises(InputError, match="built-in samples: berea120"):
        load_sample("bentheimer")


def test_mhd_zlib_compressed_and_tif_data_file(tmp_path, rng):
    import zlib

    a = _binary(rng, (3, 4, 5))
    (tmp_path / "z.zraw").write_bytes(zlib.compress(a.tobytes("F")))
    _mhd(tmp_path / "z.mhd", "z.zraw", a.shape, spacing="1e-6 1e-6 1e-6", extra="CompressedData = True\n")
    np.testing.assert_array_equal(read_image(tmp_path / "z.mhd").phases, a)
    # pnextract: a .tif data file; the header's spacing wins over the TIFF tags
    tifffile.imwrite(tmp_path / "t.tif", a.transpose(2, 1, 0), photometric="minisblack")
    _mhd(tmp_path / "t.mhd", "t.tif", a.shape, spacing="1.5 1.5 1.5")
    img = read_image(tmp_path / "t.mhd")
    np.testing.assert_array_equal(img.phases, a)
    assert img.voxel_size == 1.5e-6


def test_explicit_voxel_size_overrides_unusable_file_spacing(tmp_path, rng):
    """An explicit voxel size makes a non-cubic or unit-less spacing usable; it also sets the
    scale of the Offset (metres per file unit = voxel_size / spacing)."""
    a = _binary(rng, (3, 3, 3))
    a.ravel(order="F").tofile(tmp_path / "o.raw")
    _mhd(tmp_path / "o.mhd", "o.raw", a.shape, spacing="0.005 0.005 0.005", extra="Offset = 0.0025 0.0125 0.0025\n")
    img = read_image(tmp_path / "o.mhd", voxel_size=5e-6)  # ambiguous unit: the user's size decides
    assert img.voxel_size == 5e-6
    np.testing.assert_allclose(img.origin, [0, 10e-6, 0], atol=1e-20)
    _mhd(tmp_path / "n.mhd", "o.raw", a.shape, spacing="1 1 2")
    assert read_image(tmp_path / "n.mhd", voxel_size=1e-6).voxel_size == 1e-6


def test_tiff_lzw_needs_imagecodecs_or_reads(tmp_path, rng):
    """LZW (common for micro-CT stacks) is decoded by tifffile only through imagecodecs."""
    from PIL import Image

    vol = _binary(rng, (9, 8, 3))
    pages = [Image.fromarray(p * 255) for p in vol.transpose(2, 1, 0)]
    pages[0].save(tmp_path / "lzw.tif", save_all=True, append_images=pages[1:], compression="tiff_lzw")
    try:
        import imagecodecs  # noqa: F401
    except ImportError:
        with pytest.raises(InputError, match="pip install imagecodecs"):
            read_image(tmp_path / "lzw.tif", voxel_size=1e-6)
    else:
        np.testing.assert_array_equal(read_image(tmp_path / "lzw.tif", voxel_size=1e-6).phases, vol)


def test_voxel_image_never_freezes_or_aliases_the_callers_array():
    ph = np.zeros((4, 3, 2), dtype=np.uint8)
    ph[1:3, :, :] = 1
    img = VoxelImage(ph, 1e-6)
    assert ph.flags.writeable  # the caller's array is untouched
    assert not img.phases.flags.writeable
    ph[0, 0, 0] = 1  # and changing it later does not change the image
    assert img.phases[0, 0, 0] == 0
    shared = VoxelImage(img.phases, 1e-6)  # a read-only array (another image's) is shared
    assert shared.phases is img.phases
