"""The user cache folder of biafc-lab: compiled kernel, converged references, stability verdicts,
parsed units. In the lowest layer (``instruments``), so that every layer can keep what it
computed once there.

``$BIAFC_CACHE_DIR`` when set, else platformdirs' user cache folder (``$XDG_CACHE_HOME/biafc-lab``
or ``~/.cache/biafc-lab`` on Linux, ``~/Library/Caches/biafc-lab`` on macOS,
``%LOCALAPPDATA%\\biafc-lab\\Cache`` on Windows). Never inside the sources, so a read-only
install works; created on demand by the writers.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    """The user cache folder of biafc-lab (created on demand by the writers)."""
    env = os.environ.get("BIAFC_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("biafc-lab", appauthor=False))
