import os

from setuptools import find_packages, setup

PACKAGE = "pneu_msgs_py"

data_files = [
    ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
    (os.path.join("share", PACKAGE), ["package.xml"]),
]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=data_files,
    install_requires=[
        "setuptools",
        "numpy>=1.26",
        "PyYAML>=6.0",
        "mcap>=1.2",
        "mcap-ros2-support>=0.5",
        "rosbags>=0.10",
        "zstandard>=0.22",
        "lz4>=4.0",
        "filelock>=3.12",
    ],
    extras_require={
        "live": ["foxglove-sdk>=0.30"],  # pneu_msgs_py.live: imported when a server starts
        "test": ["pytest", "websockets>=13"],  # colcon test runs pytest when this names it
    },
    zip_safe=True,
    maintainer="pneu developers",
    maintainer_email="pneu@example.org",
    description="pneu message contract: topic table, QoS, units, conversions, parameter dataclasses, MCAP (ros2 profile) writer and reader.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [],
    },
)
