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

The same plugin imports ``launch``, whose ``launch.logging`` makes every
logger created after it a ``LaunchLogger`` with ``propagate=False``: records
of our modules then never reach pytest's ``caplog`` (a root handler), and
tests that check a logged warning fail on a ROS machine only. Loggers created
from here on are plain ones again (no test here runs ``launch`` in-process;
``ros2 launch`` runs in a subprocess).

This file sits at the workspace root so that it applies both to ``pytest``
run at the root and to ``colcon test`` (pytest in each package's directory,
through the ``src/<pkg>/test/`` links).
"""

from __future__ import annotations

import logging

import pytest

if logging.getLoggerClass() is not logging.Logger:  # launch.logging.LaunchLogger
    logging.setLoggerClass(logging.Logger)


@pytest.hookimpl(tryfirst=True)
def pytest_pycollect_makemodule(module_path, parent):
    if module_path.name == "__init__.py":
        return None
    return pytest.Module.from_parent(parent, path=module_path)
