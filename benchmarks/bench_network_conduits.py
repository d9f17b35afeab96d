"""Where the network loses (or gains) conductance: each conduit against the voxel Stokes flow through it.

One voxel Stokes solve (``porefsi.stokes.voxel_permeability(fields=True)``) and the default
network of the same image. For every throat t between pores i and j: the voxel flow through
the interface (the voxel-centred velocity averaged onto the interface faces, times the face area)
and the drop between the two pore regions' mean voxel pressures give a *voxel conductance*
``g_vox = q_t / (P_i - P_j)``; the network's ``g_net`` is
:func:`porefsi.network.geometry.conduit_conductance`. Printed: the dissipation-weighted geometric
mean of ``g_net / g_vox`` (over conduits carrying flow; it reproduces the k ratio when the error
is in the conduits), overall and binned by throat radius, by the throat duct's share of the
conduit resistance, and by section class. (Region-mean pressures are not the pore-centre
pressures the network uses: per conduit this is a diagnosis, not a measurement.)

Usage::

    python benchmarks/bench_network_conduits.py IMAGE.npz [--crop 100,100,100,100] [--axis x]
"""

from __future__ import annotations

import argparse

import numpy as np

from porefsi.flow.permeability import absolute_permeability
from porefsi.image import VoxelImage
from porefsi.network.extract import extract_network
from porefsi.network.geometry import conduit_conductance, resistance_factors, shape_class
from porefsi.stokes import voxel_permeability


def interface_flow(labels: np.ndarray, velocity: np.ndarray, conns: np.ndarray, vs: float) -> np.ndarray:
    """Voxel flow (m³/s) through each throat's interface, from conns[:, 0] to conns[:, 1]."""
    key = {(int(a), int(b)): t for t, (a, b) in enumerate(conns)}
    q = np.zeros(conns.shape[0])
    for d in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[d], hi[d] = slice(0, -1), slice(1, None)
        la, lb = labels[tuple(lo)], labels[tuple(hi)]
        m = (la >= 0) & (lb >= 0) & (la != lb)
        u = 0.5 * (np.nan_to_num(velocity[tuple(lo)][..., d][m]) + np.nan_to_num(velocity[tuple(hi)][..., d][m]))
        for x, y, f in zip(la[m], lb[m], u * vs * vs, strict=True):
            t = key.get((min(int(x), int(y)), max(int(x), int(y))))
            if t is not None:
                q[t] += f if x < y else -f
    return q


def _bins(name, values, edges, w, lr) -> None:
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        s = (values >= lo) & (values < hi)
        if s.any():
            gm = float(np.exp((w[s] * lr[s]).sum() / w[s].sum()))
            print(f"  {name} [{lo:g}, {hi:g}): {int(s.sum()):4d} conduits, dissipation {w[s].sum():.3f}, "
                  f"g_net/g_vox {gm:.3f}")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("image")
    ap.add_argument("--crop", help="x0,y0,z0,n: an n³ crop at that offset")
    ap.add_argument("--axis", default="x")
    a = ap.parse_args(argv)
    z = np.load(a.image)
    img, vs = z["image"].astype(np.uint8), float(z["voxel_size_m"])
    if a.crop:
        *o, n = (int(v) for v in a.crop.split(","))
        img = img[tuple(slice(s, s + n) for s in o)]
    im = VoxelImage(np.ascontiguousarray(img), voxel_size=vs)
    ext = extract_network(im)
    net, lab = ext.network, np.asarray(ext.labels)
    kn = absolute_permeability(net, a.axis).k_mD
    r = voxel_permeability(im, a.axis, fields=True)
    print(f"{a.image} {img.shape} axis {a.axis}: network {kn:.0f} mD, voxel {r.k_mD:.0f} mD, ratio {kn / r.k_mD:.3f}")
    P = np.asarray(r.pressure)
    ok = (lab >= 0) & np.isfinite(P)
    cnt = np.bincount(lab[ok], minlength=net.n_pores)
    Pm = np.bincount(lab[ok], weights=P[ok], minlength=net.n_pores) / np.maximum(cnt, 1)
    conns = net.throat_conns
    q = interface_flow(lab, np.asarray(r.velocity), conns, vs)
    dP = Pm[conns[:, 0]] - Pm[conns[:, 1]]
    with np.errstate(divide="ignore", invalid="ignore"):
        gv = q / dP
    good = np.isfinite(gv) & (gv > 0) & (np.abs(dP) > 1e-3 * np.abs(dP).max())
    gn = conduit_conductance(net, 1e-3)[good]
    w = (q * dP)[good] / (q * dP)[good].sum()
    lr = np.log(gn / gv[good])
    gm = float(np.exp((w * lr).sum()))
    print(f"  {int(good.sum())} of {net.n_throats} conduits; dissipation-weighted g_net/g_vox {gm:.3f}, "
          f"median {float(np.exp(np.median(lr))):.3f}")
    h = resistance_factors(net)[good]
    _bins("throat radius (voxels)", net.throat_radius[good] / vs, [0, 1.5, 2, 2.5, 3, 4, 99], w, lr)
    _bins("throat share of resistance", h[:, 1] / h.sum(axis=1), [0, 0.5, 0.75, 0.9, 1.01], w, lr)
    _bins("class (0 tri, 1 sq, 2 circ)", shape_class(net.throat_shape_factor)[good], [0, 1, 2, 3], w, lr)
    return {"k_ratio": kn / r.k_mD, "conduit_ratio": gm}


if __name__ == "__main__":
    main()
