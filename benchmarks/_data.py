"""Where the benchmarks find the real rock images (the 400³ Berea and the others of ``shared/data``).

The images are not part of the repository. ``data_dir()`` is, in this order: the folder named
by the environment variable ``POREFSI_DATA``; ``shared/data`` next to the checkout or one level
above it (a git worktree of the checkout); else ``None``. A benchmark that needs an image and
finds none says so in one line and names ``POREFSI_DATA`` and its ``--image``/``--data`` option.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def data_dir() -> Path | None:
    """The folder holding the real rock images, or ``None`` when there is none (see the module)."""
    env = os.environ.get("POREFSI_DATA")
    if env:
        return Path(env)
    for root in (REPO.parent, REPO.parent.parent):
        if (root / "shared" / "data").is_dir():
            return root / "shared" / "data"
    return None


def data_file(name: str) -> Path:
    """``data_dir() / name``; a path under ``../shared/data`` (which may not exist) when there is no folder."""
    d = data_dir()
    return (d if d is not None else REPO.parent / "shared" / "data") / name
