"""`porefsi drainage` in a batch job (stderr a pipe) shows it is alive (issue 13, section 4), and
`--scheme adaptive` reaches the simulator and the summary (issue 16, section 1)."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from porefsi.network.lattice import lattice_network

convert = pytest.importorskip("porefsi.network.convert")

_LINE = re.compile(r"drainage: t = (\S+) / 20 s, Sw = (\S+), P_in = (\S+ Pa|- \(no pressure solve yet\)), "
                   r"(\d+) events, (\d+) pores full, (\d+) s wall")


@pytest.fixture(scope="module")
def net_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("progress")
    return convert.save_network(lattice_network((20, 10, 8), 4e-5, np.random.default_rng(2)), d / "net.npz")


@pytest.mark.parametrize("scheme", ["exact", "adaptive"])
def test_progress_lines_on_a_pipe(net_file, scheme):
    r = subprocess.run([sys.executable, "-m", "porefsi", "drainage", str(net_file), "--progress-every", "0.02",
                        "--scheme", scheme, "--json"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    rows = [_LINE.fullmatch(s) for s in lines]
    assert all(rows), lines  # nothing but progress lines
    assert len(rows) >= 3, lines
    t, sw, events, full = (np.array([float(m[i]) for m in rows]) for i in (1, 2, 4, 5))
    assert t[0] == 0.0 and events[0] == 0 and sw[0] == 1.0  # the first line: the run has started
    assert np.all(np.diff(t) >= 0) and np.all(np.diff(events) >= 0) and np.all(np.diff(sw) <= 0)
    assert events[-1] > events[0] and full[-1] > 0
    assert rows[0][3] == "- (no pressure solve yet)"  # no NaN before the first solve
    solved = [i for i, m in enumerate(rows) if m[3].endswith(" Pa")]
    assert solved and solved == list(range(solved[0], len(rows)))  # once solved, the latest solved value
    p = np.array([float(rows[i][3].removesuffix(" Pa")) for i in solved])
    assert np.isfinite(p).all() and (p > 0).all()
    if scheme == "exact":
        assert solved[0] == 1  # a solve at the first event (the adaptive scheme may certify its first fills)
    summary = json.loads(r.stdout)
    assert summary["scheme"] == scheme
    assert ("n_certified_fills" in summary) == (scheme == "adaptive")
    assert summary["final_sw"] <= sw[-1] + 1e-12
