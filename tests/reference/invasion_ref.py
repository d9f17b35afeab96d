"""A naive twin of porefsi.flow.invasion.invasion_percolation, sharing no code with porefsi.

Everything is rebuilt from the network's raw arrays with plain Python: the adjacency from
``throat_conns`` (lists), the inlet-outlet spanning pores by breadth-first search, the entry
pressures from the Young-Laplace closed form, the next pore by a linear scan of the invasion
front, and trapping by a breadth-first search of every wetting cluster after every invasion.
Quadratic in the number of pores: for networks of a few hundred pores.

Model (Wilkinson & Willemsen 1983, with the drainage model's entry rules):

- an inlet pore is entered from the inlet face at its pore-body pressure ``2 sigma cos(theta) / R``;
- a pore is entered from an invaded neighbour through their throat at ``2 sigma cos(theta) / r_t``
  (a throat is never wider than its pores, so that Young-Laplace pressure is the conduit's largest);
- the front advances through its lowest threshold (ties: the lower throat index, throats before
  inlet faces, then the lower pore index); the capillary pressure is the running maximum;
- with trapping, a wetting cluster (non-invaded pores joined by throats) that holds no
  non-invaded outlet pore is trapped and never invaded.
"""

import math
from collections import deque


def _components(n, nbrs):
    """Connected-component label of every pore (breadth-first search)."""
    label = [-1] * n
    for s in range(n):
        if label[s] >= 0:
            continue
        label[s] = s
        queue = deque([s])
        while queue:
            i = queue.popleft()
            for j, _ in nbrs[i]:
                if label[j] < 0:
                    label[j] = s
                    queue.append(j)
    return label


def _trap(n, nbrs, keep, full, trapped, outlet):
    """Mark wetting clusters without a non-invaded outlet pore as trapped (plain BFS over all)."""
    seen = [False] * n
    for s in range(n):
        if not keep[s] or full[s] or trapped[s] or seen[s]:
            continue
        cluster, queue = [s], deque([s])
        seen[s] = True
        while queue:
            i = queue.popleft()
            for j, _ in nbrs[i]:
                if keep[j] and not full[j] and not trapped[j] and not seen[j]:
                    seen[j] = True
                    cluster.append(j)
                    queue.append(j)
        if not any(outlet[i] for i in cluster):
            for i in cluster:
                trapped[i] = True


def invasion_percolation_ref(conns, pore_radius, throat_radius, pore_volume, inlet, outlet, sigma, theta_deg,
                             trapping=True, stop_at_breakthrough=False):
    """Invasion order, entry pressures, Pc and Sw after each step, trapped pores.

    Parameters are plain sequences (SI units): ``conns`` (Nt, 2) pore pairs, ``inlet``/``outlet``
    (Np,) bools of the pores on the low/high face of the flow axis.

    Returns
    -------
    dict with ``sequence`` (Np, rank or -1), ``entry`` (Np, Pa or NaN), ``via`` (Nt, rank of the
    pore invaded through the throat or -1), ``pc`` and ``sw`` (per step), ``trapped`` (Np),
    ``breakthrough`` (step index or -1), ``keep`` (Np, pores of an inlet-outlet spanning cluster).
    """
    n = len(pore_radius)
    nbrs = [[] for _ in range(n)]
    for t, (i, j) in enumerate(conns):
        nbrs[int(i)].append((int(j), t))
        nbrs[int(j)].append((int(i), t))
    label = _components(n, nbrs)
    spanning = {label[i] for i in range(n) if inlet[i]} & {label[i] for i in range(n) if outlet[i]}
    keep = [label[i] in spanning for i in range(n)]
    cos = math.cos(math.radians(theta_deg))

    def young_laplace(r):
        return 2.0 * sigma * cos / r

    full, trapped = [False] * n, [False] * n
    sequence, entry, via = [-1] * n, [math.nan] * n, [-1] * len(conns)
    pcs, sws = [], []
    total = sum(pore_volume[i] for i in range(n) if keep[i])
    stored, pc, bt = 0.0, -math.inf, -1
    while True:
        best = None  # (threshold, tie key, pore, throat)
        for x in range(n):
            if not keep[x] or full[x] or trapped[x]:
                continue
            if inlet[x]:
                cand = (young_laplace(pore_radius[x]), (1, x), x, -1)
                best = cand if best is None or cand[:2] < best[:2] else best
            for u, t in nbrs[x]:
                if keep[u] and full[u]:
                    cand = (young_laplace(throat_radius[t]), (0, t), x, t)
                    best = cand if best is None or cand[:2] < best[:2] else best
        if best is None:
            break
        thr, _, x, t = best
        step = len(pcs)
        full[x], sequence[x], entry[x] = True, step, thr
        if t >= 0:
            via[t] = step
        stored += pore_volume[x]
        pc = max(pc, thr)
        pcs.append(pc)
        sws.append(1.0 - stored / total)
        if trapping:
            _trap(n, nbrs, keep, full, trapped, outlet)
        if bt < 0 and outlet[x]:
            bt = step
            if stop_at_breakthrough:
                break
    return {"sequence": sequence, "entry": entry, "via": via, "pc": pcs, "sw": sws, "trapped": trapped,
            "breakthrough": bt, "keep": keep}


def invasion_ref_for(net, fluids, axis=0, **kw):
    """Convenience: the twin on a porefsi Network's raw arrays (only reads its fields)."""
    inlet = net.pore_faces[:, 2 * axis].tolist()
    outlet = net.pore_faces[:, 2 * axis + 1].tolist()
    return invasion_percolation_ref(net.throat_conns.tolist(), net.pore_radius.tolist(), net.throat_radius.tolist(),
                                    net.pore_volume.tolist(), inlet, outlet, fluids.sigma, fluids.theta_deg, **kw)
