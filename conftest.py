"""Collect every test module with pytest's own module collector.

On a ROS 2 machine, ``launch_testing`` registers a pytest plugin whose
``pytest_pycollect_makemodule`` imports every test module itself (pytest's
``import_path`` with ``root=None``, not this project's ``--import-mode=importlib``)
to look for ``generate_test_description``. With pytest >= 8.1 (Jazzy's
launch_testing 3.4.3 was written for pytest 7) that import mis-names the
modules, and the module-level skip of ``test_ros_shells_offline.py`` escapes
from it: ``pytest test`` then collects nothing ("found no collectors").
No file here is a launch test, so this hook (tried first, first result wins)
hands every module straight to pytest. Without ROS it is the default anyway.
"""

from __future__ import annotations

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_pycollect_makemodule(module_path, parent):
    if module_path.name == "__init__.py":
        return None
    return pytest.Module.from_parent(parent, path=module_path)
