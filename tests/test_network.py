"""Validation of the :class:`porefsi.network.network.Network` dataclass (DESIGN.md §3).

Every rejected network raises :class:`InputError` whose message names the problem; valid input
is canonicalised (``conns[:, 0] < conns[:, 1]``, pore-side lengths swapped with it), frozen and
read-only, and ``dataclasses.replace`` validates again.
"""

import dataclasses

import numpy as np
import pytest

from porefsi.errors import InputError
from porefsi.network.network import Network

VS = 1e-6
R_PORE = np.array([4e-6, 3e-6, 5e-6])  # pore radii, m
R_THROAT = np.array([2e-6, 1e-6])  # throat radii, m, below both pore radii of each throat
L_THROAT = np.array([1e-5, 2e-5])
L_PORE = np.array([[1e-6, 2e-6], [3e-6, 4e-6]])  # different on each side, so a swap shows


def fields(**changes):
    """Keyword arguments of a valid 3-pore chain 0 - 1 - 2, with ``changes`` applied."""
    f = dict(
        pore_coords=np.array([[1e-5, 5e-6, 5e-6], [3e-5, 5e-6, 5e-6], [5e-5, 5e-6, 5e-6]]),
        pore_radius=R_PORE.copy(),
        pore_volume=np.array([1e-16, 2e-16, 3e-16]),
        throat_conns=np.array([[0, 1], [1, 2]]),
        throat_radius=R_THROAT.copy(),
        throat_length=L_THROAT.copy(),
        throat_pore_length=L_PORE.copy(),
        pore_faces=np.array([[1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]], bool),
        voxel_size=VS,
        shape=(60, 10, 10),
    )
    f.update(changes)
    return f


def rejects(*words, **changes):
    with pytest.raises(InputError) as err:
        Network(**fields(**changes))
    msg = str(err.value)
    for w in words:
        assert w.lower() in msg.lower(), (w, msg)
    return msg


def test_valid_network_builds():
    net = Network(**fields())
    assert (net.n_pores, net.n_throats) == (3, 2)
    np.testing.assert_array_equal(net.coordination, [1, 2, 1])


def test_self_loop_rejected():
    msg = rejects("itself", "throat 1", "pore 2", throat_conns=np.array([[0, 1], [2, 2]]))
    assert "throat_conns" in msg  # the fix names the field to correct


@pytest.mark.parametrize("second", [[0, 1], [1, 0]], ids=["same order", "reversed"])
def test_duplicate_throat_rejected_in_either_order(second):
    rejects("duplicate throat", "(0, 1)", throat_conns=np.array([[0, 1], second]),
            throat_radius=np.array([1e-6, 1e-6]))


def test_throat_wider_than_smaller_pore_rejected():
    # Throat 1 joins pores 1 (3 um) and 2 (5 um): 4 um is below the larger radius but above the smaller.
    msg = rejects("throat 1", "exceeds the smaller", throat_radius=np.array([2e-6, 4e-6]))
    assert "3e-06" in msg and "4e-06" in msg, msg
    # Equal to the smaller pore radius is allowed (a throat as wide as its pore).
    Network(**fields(throat_radius=np.array([2e-6, 3e-6])))


@pytest.mark.parametrize("value", [0.0, -1e-6], ids=["zero", "negative"])
def test_non_positive_throat_length_rejected(value):
    rejects("throat_length", "> 0", "entry 1", throat_length=np.array([1e-5, value]))


@pytest.mark.parametrize("value", [0.0, -1e-6], ids=["zero", "negative"])
@pytest.mark.parametrize("side", [0, 1])
def test_non_positive_pore_side_length_rejected(value, side):
    tpl = L_PORE.copy()
    tpl[0, side] = value
    rejects("throat_pore_length", "> 0", "entry 0", throat_pore_length=tpl)


@pytest.mark.parametrize("name", ["pore_radius", "pore_volume", "throat_radius"])
def test_non_positive_sizes_rejected(name):
    a = fields()[name].copy()
    a[0] = 0.0
    rejects(name, "> 0", **{name: a})


@pytest.mark.parametrize(
    "name", ["pore_coords", "pore_radius", "pore_volume", "throat_radius", "throat_length", "throat_pore_length"]
)
@pytest.mark.parametrize("bad", [np.nan, np.inf], ids=["nan", "inf"])
def test_nan_and_inf_rejected(name, bad):
    a = fields()[name].astype(float)
    a.reshape(-1)[0] = bad
    rejects(name, "nan or infinite", **{name: a})


@pytest.mark.parametrize("conns", [[[0, 1], [1, 3]], [[-1, 1], [1, 2]]], ids=["too large", "negative"])
def test_out_of_range_conns_rejected(conns):
    rejects("throat_conns", "outside 0..2", throat_conns=np.array(conns))


def test_float_conns_rejected():
    rejects("throat_conns", "integers", "float", throat_conns=np.array([[0.0, 1.0], [1.0, 2.0]]))


def test_wrong_shapes_rejected():
    rejects("throat_radius", "shape (2,)", throat_radius=np.array([1e-6]))
    rejects("pore_coords", "(Np, 3)", pore_coords=np.zeros((3, 2)))
    rejects("throat_conns", "(Nt, 2)", throat_conns=np.array([0, 1, 2]))


@pytest.mark.parametrize("value", ["abc", None, 0.0, -1e-6, np.nan])
def test_bad_voxel_size_rejected(value):
    rejects("voxel_size", "metres", repr(value), voxel_size=value)


@pytest.mark.parametrize("value", [(10, 10), (10, 0, 10), ("a", 1, 1)])
def test_bad_shape_rejected(value):
    rejects("Network.shape", "3 positive ints", shape=value)


def test_non_numeric_array_rejected():
    rejects("pore_radius", "numbers", pore_radius=["a", "b", "c"])


def test_reversed_conns_are_canonicalised_with_pore_side_lengths_swapped():
    conns = np.array([[1, 0], [1, 2]])  # throat 0 given from pore 1 to pore 0
    net = Network(**fields(throat_conns=conns))
    np.testing.assert_array_equal(net.throat_conns, [[0, 1], [1, 2]])
    # Throat 0's side lengths follow its pores: the length inside pore 1 was column 0, now column 1.
    np.testing.assert_array_equal(net.throat_pore_length, [L_PORE[0, ::-1], L_PORE[1]])
    # Nothing else about the throats moves, and the caller's arrays are untouched.
    np.testing.assert_array_equal(net.throat_radius, R_THROAT)
    np.testing.assert_array_equal(net.throat_length, L_THROAT)
    np.testing.assert_array_equal(conns, [[1, 0], [1, 2]])
    # Same network as the canonical input of the same conduits.
    ref = Network(**fields(throat_pore_length=np.array([L_PORE[0, ::-1], L_PORE[1]])))
    for f in ("throat_conns", "throat_pore_length", "throat_radius", "throat_length"):
        np.testing.assert_array_equal(getattr(net, f), getattr(ref, f))


def test_arrays_read_only_and_dataclass_frozen():
    net = Network(**fields())
    for f in dataclasses.fields(Network):
        v = getattr(net, f.name)
        if isinstance(v, np.ndarray):
            assert not v.flags.writeable, f.name
            with pytest.raises(ValueError, match="read-only"):
                v.reshape(-1)[0] = v.reshape(-1)[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        net.voxel_size = 2 * VS
    with pytest.raises(dataclasses.FrozenInstanceError):
        net.pore_radius = R_PORE


def test_inputs_not_modified_or_aliased():
    f = fields()
    net = Network(**f)
    for name in ("pore_coords", "pore_radius", "throat_radius", "throat_pore_length", "pore_faces"):
        assert f[name].flags.writeable, name  # the caller's array is not frozen behind its back
    f["pore_radius"][0] = 1.0  # and changing it afterwards does not change the network
    assert net.pore_radius[0] == R_PORE[0]


def test_replace_validates_again():
    net = Network(**fields())
    with pytest.raises(InputError, match="exceeds the smaller"):
        dataclasses.replace(net, throat_radius=np.array([2e-6, 4e-6]))
    with pytest.raises(InputError, match="itself"):
        dataclasses.replace(net, throat_conns=np.array([[0, 1], [1, 1]]))
    with pytest.raises(InputError, match="duplicate throat"):
        net.replace(throat_conns=np.array([[0, 1], [1, 0]]), throat_radius=np.array([1e-6, 1e-6]))
    # A valid replacement is canonicalised like a new network and shares the untouched fields.
    new = dataclasses.replace(net, throat_conns=np.array([[1, 0], [2, 1]]))
    np.testing.assert_array_equal(new.throat_conns, net.throat_conns)
    np.testing.assert_array_equal(new.throat_pore_length, L_PORE[:, ::-1])
    assert new.pore_radius is net.pore_radius
