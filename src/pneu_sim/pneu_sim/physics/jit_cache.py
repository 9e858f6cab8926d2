"""numba's on-disk cache of a function that inlines code from other files, kept in step with them.

numba keys a cached function on its own file only (numba docs, "Cache
limitations"): a change in a file it calls is not seen, and the stale machine
code would run. :func:`refresh_cache` keeps a digest of every source beside
the cache and flushes the function's cache index when the digest differs.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

__all__ = ["refresh_cache"]


def refresh_cache(dispatcher, sources: Iterable[Path], tag: str) -> bool:
    """Flush ``dispatcher``'s cache if ``sources`` changed since the digest ``tag`` was kept;
    returns whether it flushed."""
    digest = hashlib.sha256()
    for f in sources:
        digest.update(Path(f).read_bytes())
    cache = getattr(dispatcher, "_cache", None)  # numba's Dispatcher cache (no public API)
    path = getattr(cache, "cache_path", None)
    if path is None:
        return False
    stamp = Path(path) / f"{tag}.sources"
    want = digest.hexdigest()
    try:
        if stamp.read_text() == want:
            return False
    except OSError:
        pass
    cache.flush()
    try:
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(want)
    except OSError:
        pass  # read-only cache: numba recompiles in memory
    return True
