"""The cached compiled loop is dropped when a source it is built from changes.

numba keys a cached function on its own file only; the loop inlines the plant
kernel and the mirrors from other files, so ``refresh_cache`` keeps a digest of
all of them beside the cache and flushes numba's index when it differs.
"""

from __future__ import annotations

from pathlib import Path

from pneu_control.fastloop import loop


class FakeCache:
    def __init__(self, path: Path):
        self.cache_path = str(path)
        self.flushes = 0

    def flush(self) -> None:
        self.flushes += 1


def test_sources_cover_every_kernel_module_and_the_plant_kernel():
    """A module that writes a @kernel is compiled into the loop: its change must flush."""
    src = Path(__file__).resolve().parents[3] / "src"
    sources = {p.resolve() for p in loop._sources()}
    kernel_modules = {
        p.resolve() for p in src.rglob("*.py") if "@kernel" in p.read_text(encoding="utf-8")
    }
    assert kernel_modules, "no kernel module found: the scan is broken"
    assert kernel_modules <= sources, sorted(str(p) for p in kernel_modules - sources)
    assert {"loop.py", "axis.py", "kernel.py"} <= {p.name for p in sources}


def test_a_changed_source_flushes_the_cache_once(tmp_path, monkeypatch):
    extra = tmp_path / "dep.py"
    extra.write_text("a = 1\n")
    real = loop._sources()
    monkeypatch.setattr(loop, "_sources", lambda: [*real, extra])
    fake = FakeCache(tmp_path / "cache")
    monkeypatch.setattr(loop.closed_loop, "_cache", fake)
    loop.refresh_cache()  # no digest yet: flush, remember
    assert fake.flushes == 1
    loop.refresh_cache()  # unchanged sources: the cache stays
    assert fake.flushes == 1
    extra.write_text("a = 2\n")
    loop.refresh_cache()
    assert fake.flushes == 2
