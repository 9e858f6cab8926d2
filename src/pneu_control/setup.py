import os
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "pneu_control"

data_files = [
    ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
    (os.path.join("share", PACKAGE), ["package.xml"]),
    (os.path.join("share", PACKAGE, "config"), sorted(glob("config/*.yaml"))),
    (  # Foxglove / PlotJuggler layouts (pneu_control/analysis/layouts.py)
        os.path.join("share", PACKAGE, "config", "layouts"),
        sorted(glob("config/layouts/*.json") + glob("config/layouts/*.xml")),
    ),
    (os.path.join("share", PACKAGE, "config", "tasks"), sorted(glob("config/tasks/*.yaml"))),
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
        "pneu_sim",
        "pneu_driver",
        "numpy>=1.26",
        "numba>=0.59",  # pneu_control.fastloop: the compiled closed loop
        "scipy>=1.16",  # sweeps: qmc (rng= keyword), rank correlation; identify: least_squares
        "threadpoolctl>=3.1",  # identify: BLAS at one thread beside the replay's workers
        "distributed>=2024.8",  # pneu sweep --executor dask
        "PyYAML>=6.0",
        "matplotlib>=3.7",
        "mcap-ros2-support>=0.5",  # pneu_control.experiment.fault_table checks bags with it
        "tqdm>=4.66",  # progress bars (cli/progress.py)
    ],
    extras_require={
        "live": ["foxglove-sdk>=0.30"],  # pneu run --live (through pneu_msgs_py.live)
        "test": ["pytest", "websockets>=13"],  # colcon test runs pytest when this names it
    },
    zip_safe=True,
    maintainer="pneu developers",
    maintainer_email="pneu@example.org",
    description="Controllers (PID, LADRC, ESO-SMC and better), references, in-process experiment runner, bag analysis and the pneu CLI.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "pneu = pneu_control.cli.main:cli",
            "linear_controller = pneu_control.nodes:linear_controller",
            "rotary_controller = pneu_control.nodes:rotary_controller",
            "logger = pneu_control.nodes:logger",
            "controller_manager = pneu_control.nodes:controller_manager",
            "bench_ros = pneu_control.bench.ros_graph:main",
            "exciter = pneu_control.nodes:exciter",
            "task_runner = pneu_control.nodes:task_runner",
        ],
    },
)
