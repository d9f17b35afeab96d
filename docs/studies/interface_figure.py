"""Figure for docs/theory.md: the two pressure -> force interfaces on one closed cavity.

Two voxelised spherical pores (radius 7 voxels) joined by a throat, closed inside a solid box,
are meshed (5-tet voxel split), the network is extracted, and both interfaces of
``porefsi.coupling`` are built through the public API with the default case settings (hull: 800
test points, eps = 0.5 R, pore-wall nodes only; traction: the wall facets of each pore's voxel
region). For 1 Pa in both pores the script prints the load-balance figures quoted in the caption
and draws the nodal forces near the mid-plane, arrows scaled alike.
Run: ``python docs/studies/interface_figure.py [OUT.png]`` (~5 s).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402

from porefsi.coupling import HullOptions, TractionOptions  # noqa: E402
from porefsi.image.voxel_image import VoxelImage  # noqa: E402
from porefsi.network.extract import extract_network  # noqa: E402
from porefsi.solid import mesh_solid  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "figures" / "interface_hull_traction.png"


def cavity_image(radius: float = 7.0, throat: float = 2.5, spacing: int = 17, margin: int = 10,
                 voxel_size: float = 5e-6) -> VoxelImage:
    """Two spherical pores joined by a cylindrical throat, closed inside a solid box."""
    shape = (2 * margin + spacing + 1, 2 * margin + 1, 2 * margin + 1)
    x, y, z = np.meshgrid(*[np.arange(n, dtype=float) for n in shape], indexing="ij")
    c0, c1 = np.array([margin, margin, margin]), np.array([margin + spacing, margin, margin])
    pore = np.zeros(shape, bool)
    for c in (c0, c1):
        pore |= (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 <= radius**2
    pore |= (x >= c0[0]) & (x <= c1[0]) & ((y - c0[1]) ** 2 + (z - c0[2]) ** 2 <= throat**2)
    return VoxelImage(pore.astype(np.uint8), voxel_size)


def main(out: Path = OUT) -> dict:
    """Draw the figure to ``out``; return the load-balance figures of both interfaces."""
    import matplotlib.pyplot as plt

    img = cavity_image()
    ext = extract_network(img)
    net = ext.network
    assert (net.n_pores, net.n_throats) == (2, 1), (net.n_pores, net.n_throats)
    mesh = mesh_solid(img, coarsen=1, support_axis="z").mesh
    P = np.array([1.0, 1.0])  # Pa: the same pressure in both pores, so the cavity is closed
    stats, forces = {}, {}
    for method in ("hull", "traction"):
        opts = HullOptions() if method == "hull" else TractionOptions()  # the defaults of a case
        itf = opts.build(net, ext.labels, mesh, voxel_size=img.voxel_size, origin=img.origin)
        f = itf.nodal_forces(P)
        forces[method] = f
        mag = np.linalg.norm(f, axis=1)
        PA = float(P @ itf.wall_area)
        stats[method] = {
            "loaded_nodes": int(np.count_nonzero(mag)),
            "sum_abs_over_PA": float(mag.sum() / PA),
            "resultant_over_PA": float(np.linalg.norm(f.sum(axis=0)) / PA),
            "wall_area_m2": itf.wall_area.tolist(),
            "load_balance_error": itf.load_balance_error(P),
        }
    stats["sphere_areas_m2"] = (4 * np.pi * net.pore_radius**2).tolist()
    stats["pore_radius_m"] = net.pore_radius.tolist()

    c = net.pore_coords.mean(axis=0)
    h = img.voxel_size
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    scale = max(np.linalg.norm(forces[m], axis=1).max() for m in forces)
    titles = {"hull": "hull (paper): 800 test points, each lumped on its nearest wall node",
              "traction": "consistent traction: $-P\\,\\mathbf{n}$ on the pores' wall facets"}
    for ax, method in zip(axes, ("hull", "traction"), strict=True):
        f = forces[method]
        # The two node layers either side of the mid-plane y = centre, seen along y.
        keep = (np.linalg.norm(f, axis=1) > 0) & (np.abs(mesh.points[:, 1] - c[1]) <= 0.5 * h + 1e-12)
        p = (mesh.points[keep] - c) * 1e6
        v = f[keep] / scale
        ax.quiver(p[:, 0], p[:, 2], v[:, 0], v[:, 2], color="C3", angles="xy", scale_units="xy",
                  scale=1.0 / (2.5 * h * 1e6), width=0.004)
        ax.plot(p[:, 0], p[:, 2], "k.", ms=3)
        t = np.linspace(0, 2 * np.pi, 200)
        for pc, R in zip(net.pore_coords, net.pore_radius, strict=True):
            q = (pc - c) * 1e6
            ax.plot(q[0] + R * 1e6 * np.cos(t), q[2] + R * 1e6 * np.sin(t), "b--", lw=0.8)
            if method == "hull":
                ax.plot(q[0] + 1.5 * R * 1e6 * np.cos(t), q[2] + 1.5 * R * 1e6 * np.sin(t), "b:", lw=0.8)
        ax.set_title(titles[method], fontsize=10)
        ax.set_xlabel("x (µm)")
        ax.set_ylabel("z (µm)")
        ax.set_xlim(-100, 100)
        ax.set_ylim(-60, 60)
        ax.set_aspect("equal")
    fig.suptitle("1 Pa in a closed two-pore cavity: nodal forces near the mid-plane "
                 "(dashed: pore spheres, dotted: R + ε)", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return stats


if __name__ == "__main__":
    res = main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
    for k, v in res.items():
        print(k, v)
