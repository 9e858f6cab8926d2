import os
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "pneu_driver"

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
        "numpy>=1.26",
        "PyYAML>=6.0",
        "filelock>=3.12",
        "nidaqmx>=1.7,<1.8",
    ],
    extras_require={"test": ["pytest"]},  # colcon test runs pytest when this names it
    zip_safe=True,
    maintainer="pneu developers",
    maintainer_email="pneu@example.org",
    description="Driver for the NI PCI-6221 rig through nidaqmx (hardware-timed 1 kHz), DAQ scaling and the safety supervisor.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ["driver_node = pneu_driver.nodes:driver_node"],
    },
)
