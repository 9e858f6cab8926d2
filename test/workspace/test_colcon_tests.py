"""``colcon test`` reaches every test through the packages, ``pytest`` at the root runs each once.

colcon runs ``python -m pytest`` with no path from each package's source
directory (colcon-core's pytest step, chosen when setup.py names pytest in
``extras_require["test"]``). Each ``src/<pkg>/test/`` holds links to that
package's areas of the workspace's ``test/``; pytest follows them. The root
``pyproject.toml`` (``testpaths = ["test"]``) and ``conftest.py`` apply to both
ways of running. Checked from the files, then by collecting: the tests
collected from the four package directories are exactly the tests collected
at the root, each once.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import tomllib
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src"
PACKAGES = sorted(p.name for p in SRC.iterdir() if (p / "package.xml").is_file())
AREAS = sorted(
    d.name for d in (ROOT / "test").iterdir() if d.is_dir() and any(d.rglob("test_*.py"))
)


def _links() -> dict[str, list[str]]:
    """test area -> the packages that link it."""
    out: dict[str, list[str]] = {}
    for pkg in PACKAGES:
        for link in sorted((SRC / pkg / "test").iterdir()):
            assert link.is_symlink(), f"src/{pkg}/test/{link.name} must be a link into test/"
            target = link.resolve()
            assert target.parent == ROOT / "test" and target.name == link.name, link
            assert not os.path.isabs(os.readlink(link)), f"{link}: relative link, please"
            out.setdefault(link.name, []).append(pkg)
    return out


def test_every_test_area_is_linked_from_exactly_one_package():
    links = _links()
    assert sorted(links) == AREAS
    assert all(len(pkgs) == 1 for pkgs in links.values()), links
    owner = {area: pkgs[0] for area, pkgs in links.items()}
    assert owner["msgs"] == "pneu_msgs_py" and owner["driver"] == "pneu_driver"
    assert owner["sim"] == "pneu_sim" and owner["control"] == "pneu_control"


def test_colcon_picks_pytest_and_the_root_config_applies():
    spec = importlib.util.spec_from_file_location(
        "_layout", Path(__file__).with_name("test_layout.py")
    )
    layout = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(layout)
    for pkg in PACKAGES:  # colcon-core: has_test_dependency(setup_py_data, "pytest")
        assert "pytest" in layout._setup_kwargs(pkg)["extras_require"]["test"], pkg
        cfg = (SRC / pkg / "setup.cfg").read_text()
        assert "[tool:pytest]" not in cfg, f"{pkg}/setup.cfg would shadow the root pytest config"
        assert not (SRC / pkg / "pytest.ini").exists()
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["tool"]["pytest"]["ini_options"]["testpaths"] == ["test"]
    assert (ROOT / "conftest.py").is_file()  # launch_testing's collector hook, for both ways


def _collect(cwd: Path) -> list[str]:
    """Test ids collected by ``python -m pytest`` run in ``cwd`` as colcon does, as real paths."""
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_ADDOPTS"}  # colcon's junit target
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode in (0, 5), proc.stdout[-2000:] + proc.stderr[-2000:]
    ids = []
    for line in proc.stdout.splitlines():
        m = re.match(r"^(\S+?\.py)(::.*)$", line)
        if m:
            ids.append(str((ROOT / m.group(1)).resolve().relative_to(ROOT)) + m.group(2))
    return ids


@pytest.mark.slow
def test_the_packages_collect_exactly_the_root_tests_once():
    at_root = _collect(ROOT)
    from_packages = [i for pkg in PACKAGES for i in _collect(SRC / pkg)]
    assert at_root and all(i.startswith("test/") for i in at_root)
    dup = [i for i, n in Counter(from_packages).items() if n > 1]
    assert not dup, f"collected twice through the packages: {dup[:5]}"
    assert sorted(from_packages) == sorted(at_root)
