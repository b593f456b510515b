"""Where wingopt keeps caches: the user's cache directory, never the installed package.

numba's compiled kernels (``@njit(cache=True)``) are written next to their module by default, that
is inside the installed package (a read-only site-packages, a shared install, a container image).
:func:`use_user_cache` points numba at ``<user cache>/numba`` (``NUMBA_CACHE_DIR``) before it compiles,
unless the user set ``NUMBA_CACHE_DIR``. The user cache directory: ``platformdirs.user_cache_dir``
when platformdirs is installed, else ``$XDG_CACHE_HOME/wingopt``, else ``~/.cache/wingopt``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["user_cache_dir", "use_user_cache"]


def user_cache_dir() -> Path:
    """The user's cache directory for wingopt (module docstring); ``WINGOPT_CACHE_DIR`` overrides it."""
    if os.environ.get("WINGOPT_CACHE_DIR"):
        return Path(os.environ["WINGOPT_CACHE_DIR"]).expanduser()
    try:
        import platformdirs  # optional: the platform's convention (macOS, Windows)

        return Path(platformdirs.user_cache_dir("wingopt"))
    except ImportError:
        pass
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "wingopt"


def use_user_cache() -> str:
    """Set ``NUMBA_CACHE_DIR`` to ``<user cache>/numba`` unless the user set it; returns the directory.

    numba reads the variable when it is first imported; when it is already imported (the user
    imported it first) its config is set too, so the kernels compiled later go there as well.
    """
    path = os.environ.get("NUMBA_CACHE_DIR")
    if not path:
        path = str(user_cache_dir() / "numba")
        os.environ["NUMBA_CACHE_DIR"] = path
        config = sys.modules.get("numba.core.config")
        if config is not None:
            config.CACHE_DIR = path
    return path
