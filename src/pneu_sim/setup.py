import os
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "pneu_sim"

data_files = [
    ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
    (os.path.join("share", PACKAGE), ["package.xml"]),
    (os.path.join("share", PACKAGE, "config"), sorted(glob("config/*.yaml"))),
    (  # Foxglove / PlotJuggler layouts (pneu_control/analysis/layouts.py)
        os.path.join("share", PACKAGE, "config", "layouts"),
        sorted(glob("config/layouts/*.json") + glob("config/layouts/*.xml")),
    ),
    (os.path.join("share", PACKAGE, "launch"), sorted(glob("launch/*.launch.py"))),
]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=data_files,
    install_requires=[
        "setuptools",
        "pneu_msgs_py",
        "pneu_driver",
        "numpy>=1.26",
        "numba>=0.59",
        "PyYAML>=6.0",
    ],
    extras_require={"test": ["pytest"]},  # colcon test runs pytest when this names it
    zip_safe=True,
    maintainer="pneu developers",
    maintainer_email="pneu@example.org",
    description="Physics twin of the linear-rotary pneumatic actuator (Jia et al.) and its ROS 2 sim node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ["sim_node = pneu_sim.nodes:sim_node"],
        # the twin as a DAQ, found by name by pneu_driver (backend: sim) without an import
        "pneu_driver.backends": ["sim = pneu_sim.daq_sim.backend:make_backend"],
    },
)
