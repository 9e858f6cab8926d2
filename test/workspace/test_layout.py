"""The colcon/ament_python layout, read from the files (no ROS, no colcon needed).

For each ``src/<pkg>``: package.xml (format 3, ament_python, an exec_depend
for everything the package imports), setup.py (data_files with the ament
resource marker, package.xml, config and launch; console_scripts pointing at
functions that exist), setup.cfg (script dirs where ``ros2 run`` looks),
``resource/<pkg>``. Launch files are executed against stand-ins for
``launch``/``launch_ros`` and every node they start is checked: executable
exists in that package, parameter files exist in the installed config,
parameter names are ones the node declares, with the declared type.
"""

from __future__ import annotations

import ast
import configparser
import dataclasses
import runpy
import sys
import types
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src"
PACKAGES = sorted(p.name for p in SRC.iterdir() if (p / "package.xml").is_file())
PROJECT = {"pneu_msgs_py", "pneu_sim", "pneu_control", "pneu_driver"}

# import name -> rosdep key / ROS package of the exec_depend it needs
ROS_DEPS = {
    m: m
    for m in (
        "rclpy",
        "sensor_msgs",
        "std_msgs",
        "std_srvs",
        "diagnostic_msgs",
        "rosgraph_msgs",
        "trajectory_msgs",
        "rcl_interfaces",
        "builtin_interfaces",
        "launch",
        "sros2",
        "launch_ros",
        "ament_index_python",
    )
}
ROSDEP_PY = {
    "numpy": "python3-numpy",
    "yaml": "python3-yaml",
    "numba": "python3-numba",
    "scipy": "python3-scipy",
    "matplotlib": "python3-matplotlib",
    "tqdm": "python3-tqdm",
    "filelock": "python3-filelock",
    "threadpoolctl": "python3-threadpoolctl",
    "cryptography": "python3-cryptography",
}
# pip-only libraries (no rosdep key): must be in setup.py install_requires instead
PIP_ONLY = {
    "mcap": "mcap",
    "mcap_ros2": "mcap-ros2-support",
    "rosbags": "rosbags",
    "zstandard": "zstandard",
    "nidaqmx": "nidaqmx",
    "foxglove": "foxglove-sdk",  # optional (extras_require "live"), imported when used
    "distributed": "distributed",
}
OPTIONAL = {"lz4"}  # imported lazily only for compression="lz4"
# DESIGN §2: dependency direction between the project's packages
ALLOWED_PROJECT_IMPORTS = {
    "pneu_msgs_py": set(),
    "pneu_driver": {"pneu_msgs_py"},
    "pneu_sim": {"pneu_msgs_py", "pneu_driver"},
    "pneu_control": {"pneu_msgs_py", "pneu_sim", "pneu_driver"},
}
ROS_ONLY = {
    "rclpy",
    "sensor_msgs",
    "std_msgs",
    "std_srvs",
    "diagnostic_msgs",
    "rosgraph_msgs",
    "trajectory_msgs",
    "rcl_interfaces",
}


def _imports(path: Path) -> tuple[set[str], set[str]]:
    """(all absolute import roots, roots imported at module top level)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    every, top = set(), set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name.split(".")[0] for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module.split(".")[0]]
        every.update(names)
    for node in tree.body:
        if isinstance(node, ast.Import):
            top.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            top.add(node.module.split(".")[0])
    return every, top


def _package_xml(pkg: str) -> ET.Element:
    return ET.parse(SRC / pkg / "package.xml").getroot()


def _setup_kwargs(pkg: str) -> dict[str, Any]:
    """Run setup.py with setuptools.setup replaced; return its keyword arguments."""
    import os

    import setuptools

    captured: dict[str, Any] = {}
    old_setup, old_cwd = setuptools.setup, os.getcwd()
    setuptools.setup = lambda **kw: captured.update(kw)
    try:
        os.chdir(SRC / pkg)
        runpy.run_path(str(SRC / pkg / "setup.py"), run_name="__main__")
    finally:
        setuptools.setup = old_setup
        os.chdir(old_cwd)
    return captured


def _data_files(pkg: str) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for dest, files in _setup_kwargs(pkg)["data_files"]:
        out.setdefault(dest.replace("\\", "/"), []).extend(files)
    return out


def _console_scripts(pkg: str) -> dict[str, str]:
    eps = _setup_kwargs(pkg).get("entry_points", {}).get("console_scripts", [])
    return {name.strip(): target.strip() for name, target in (e.split("=", 1) for e in eps)}


@pytest.mark.parametrize("pkg", PACKAGES)
def test_package_xml_format_3_ament_python(pkg):
    root = _package_xml(pkg)
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == pkg
    assert root.findtext("export/build_type") == "ament_python"
    for tag in ("version", "description", "maintainer", "license"):
        assert (root.findtext(tag) or "").strip(), f"{pkg}/package.xml: <{tag}> empty"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_exec_depends_cover_every_import(pkg):
    root = _package_xml(pkg)
    deps = {e.text.strip() for e in root.findall("exec_depend")}
    kwargs = _setup_kwargs(pkg)
    extras = [r for reqs in kwargs.get("extras_require", {}).values() for r in reqs]
    requires = " ".join(kwargs.get("install_requires", []) + extras)
    stdlib = set(sys.stdlib_module_names)
    files = sorted((SRC / pkg / pkg).rglob("*.py")) + sorted((SRC / pkg / "launch").glob("*.py"))
    missing, unknown, wrong_way = [], [], []
    for f in files:
        every, _ = _imports(f)
        for mod in sorted(every - stdlib - {pkg}):
            where = f"{f.relative_to(SRC)}: {mod}"
            if mod in ROS_DEPS:
                if ROS_DEPS[mod] not in deps:
                    missing.append(f"{where} -> <exec_depend>{ROS_DEPS[mod]}</exec_depend>")
            elif mod in ROSDEP_PY:
                if ROSDEP_PY[mod] not in deps:
                    missing.append(f"{where} -> <exec_depend>{ROSDEP_PY[mod]}</exec_depend>")
            elif mod in PROJECT:
                if mod not in ALLOWED_PROJECT_IMPORTS[pkg]:
                    wrong_way.append(where)
                elif mod not in deps:
                    missing.append(f"{where} -> <exec_depend>{mod}</exec_depend>")
            elif mod in PIP_ONLY:
                if PIP_ONLY[mod] not in requires:
                    missing.append(f"{where} -> install_requires {PIP_ONLY[mod]}")
            elif mod not in OPTIONAL:
                unknown.append(where)
    assert not wrong_way, f"imports against the dependency direction (DESIGN §2): {wrong_way}"
    assert not unknown, f"imports this test does not know how to map to a dependency: {unknown}"
    assert not missing, f"{pkg}: dependencies not declared:\n  " + "\n  ".join(missing)


def _role(pkg: str, f: Path) -> str:
    """The sub-package (role folder) a module of ``pkg`` lives in."""
    parts = f.relative_to(SRC / pkg / pkg).parts
    return parts[0] if len(parts) > 1 else ""


# role folders per package: the tree reads like the architecture (ARCHITECTURE.md)
ROLES = {
    "pneu_msgs_py": {"contract", "params", "bag", "live", "lifecycle", "nodes", "bench"},
    "pneu_sim": {"physics", "cycle", "faults", "daq_sim", "nodes", "cli", "bench"},
    "pneu_control": {
        "algorithms",
        "observers",
        "controller",
        "experiment",
        "fastloop",
        "analysis",
        "sweep",
        "sysid",
        "task",
        "nodes",
        "cli",
        "bench",
    },
    "pneu_driver": {"daq", "loop", "safety", "nodes", "cli", "bench"},
}
LAUNCH_ONLY = {"launch", "launch_ros", "ament_index_python"}


@pytest.mark.parametrize("pkg", PACKAGES)
def test_every_module_lives_in_a_role_folder(pkg):
    loose = [f.name for f in (SRC / pkg / pkg).glob("*.py") if f.name != "__init__.py"]
    assert not loose, f"{pkg}: modules outside a role folder: {loose}"
    folders = {d.name for d in (SRC / pkg / pkg).iterdir() if (d / "__init__.py").is_file()}
    assert folders == ROLES[pkg]


@pytest.mark.parametrize("pkg", PACKAGES)
def test_rclpy_only_under_nodes(pkg):
    """ROS-free cores: ROS (and launch) imports at module top level only in ``nodes/``."""
    bad = []
    for f in sorted((SRC / pkg / pkg).rglob("*.py")):
        _, top = _imports(f)
        if top & (ROS_ONLY | LAUNCH_ONLY) and _role(pkg, f) != "nodes":
            bad.append(f"{f.relative_to(SRC)}: {sorted(top & (ROS_ONLY | LAUNCH_ONLY))}")
    assert not bad, f"ROS imported at top level outside nodes/: {bad}"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_nidaqmx_only_in_the_daq_backend(pkg):
    bad = [
        str(f.relative_to(SRC))
        for f in sorted((SRC / pkg / pkg).rglob("*.py"))
        if "nidaqmx" in _imports(f)[0]
        and f.relative_to(SRC / pkg / pkg).as_posix() != "daq/nidaqmx_backend.py"
    ]
    assert not bad, f"nidaqmx imported outside pneu_driver/daq/nidaqmx_backend.py: {bad}"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_argparse_only_in_cli_and_benchmarks_only_in_bench(pkg):
    """Command-line parsing lives in cli/; timing loops (perf_counter) in bench/ (and the
    runner's own wall-time figure, the driver loop's clock and the node shells)."""
    clock_ok = {"bench", "cli", "nodes", "loop", "experiment", "sysid"}  # sysid: fit progress
    bad = []
    for f in sorted((SRC / pkg / pkg).rglob("*.py")):
        role = _role(pkg, f)
        every, _ = _imports(f)
        if "argparse" in every and role not in ("cli", "bench"):
            bad.append(f"{f.relative_to(SRC)}: argparse")
        if "perf_counter(" in f.read_text(encoding="utf-8") and role not in clock_ok:
            bad.append(f"{f.relative_to(SRC)}: perf_counter")
    assert not bad, bad


@pytest.mark.parametrize("pkg", PACKAGES)
def test_setup_py_data_files_and_resource_marker(pkg):
    data = _data_files(pkg)
    assert f"resource/{pkg}" in data.get("share/ament_index/resource_index/packages", [])
    assert (SRC / pkg / "resource" / pkg).is_file()
    assert "package.xml" in data.get(f"share/{pkg}", [])
    for sub, patterns in (
        ("config", ("*.yaml",)),
        ("config/layouts", ("*.json", "*.xml")),  # viewer layouts
        ("launch", ("*.launch.py",)),
    ):
        present = sorted(
            f"{sub}/{p.name}" for pattern in patterns for p in (SRC / pkg / sub).glob(pattern)
        )
        if present:
            assert sorted(data.get(f"share/{pkg}/{sub}", [])) == present, (
                f"{pkg}: {sub} not installed"
            )
    for files in data.values():
        for f in files:
            assert (SRC / pkg / f).exists(), f"{pkg}/setup.py installs missing file {f}"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_console_scripts_point_at_existing_functions(pkg):
    for name, target in _console_scripts(pkg).items():
        module, _, func = target.partition(":")
        base = SRC / pkg / module.replace(".", "/")
        path = (
            base.with_suffix(".py") if base.with_suffix(".py").is_file() else base / "__init__.py"
        )
        assert path.is_file(), f"{pkg}: console script {name} -> {target}: no {path}"
        tree = ast.parse(path.read_text(encoding="utf-8"))
        defs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        # a node's entry: name = node_entry("module", "function") -- that function must exist
        entries = {
            n.targets[0].id: [a.value for a in n.value.args]
            for n in tree.body
            if isinstance(n, ast.Assign)
            and isinstance(n.value, ast.Call)
            and getattr(n.value.func, "id", "") == "node_entry"
        }
        assert func in defs or func in entries, f"{pkg}: console script {name} -> {target}"
        if func in entries:
            mod, fn = entries[func]
            node_tree = ast.parse((SRC / pkg / (mod.replace(".", "/") + ".py")).read_text())
            assert fn in {n.name for n in node_tree.body if isinstance(n, ast.FunctionDef)}


@pytest.mark.parametrize("pkg", PACKAGES)
def test_setup_cfg_script_dirs(pkg):
    cfg = configparser.ConfigParser()
    cfg.read(SRC / pkg / "setup.cfg")
    assert cfg.get("develop", "script_dir") == f"$base/lib/{pkg}"
    assert cfg.get("install", "install_scripts") == f"$base/lib/{pkg}"


def test_node_executables_are_registered():
    scripts = {pkg: _console_scripts(pkg) for pkg in PACKAGES}
    for pkg, exe in (
        ("pneu_sim", "sim_node"),
        ("pneu_driver", "driver_node"),
        *(
            ("pneu_control", e)
            for e in ("linear_controller", "rotary_controller", "logger", "task_runner")
        ),
    ):
        assert scripts[pkg][exe] == f"{pkg}.nodes:{exe}"  # node_entry: imported under a guard


# --- launch files, executed against stand-ins -------------------------------


class _Action:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _Config:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


def _fake_launch_modules() -> dict[str, types.ModuleType]:
    mods = {}

    def mod(name, **attrs):
        m = types.ModuleType(name)
        m.__dict__.update(attrs)
        mods[name] = m
        return m

    share = lambda pkg: str(SRC / pkg)  # noqa: E731 -- src/<pkg>/config is what colcon installs
    mod("ament_index_python")
    mod("ament_index_python.packages", get_package_share_directory=share)
    mod("launch", LaunchDescription=lambda entities: list(entities))
    mod(
        "launch.actions",
        DeclareLaunchArgument=type("DeclareLaunchArgument", (_Action,), {}),
        OpaqueFunction=type("OpaqueFunction", (_Action,), {}),
        Shutdown=type("Shutdown", (_Action,), {}),
        ExecuteProcess=type("ExecuteProcess", (_Action,), {}),
        SetEnvironmentVariable=type("SetEnvironmentVariable", (_Action,), {}),
    )
    mod("launch.substitutions", LaunchConfiguration=_Config)
    mod("launch_ros")
    mod("launch_ros.actions", Node=type("Node", (_Action,), {}))
    return mods


LAUNCH_FILES = sorted(SRC.glob("*/launch/*.launch.py"))


def _run_launch(path: Path, overrides: dict[str, str]) -> list[_Action]:
    mods = _fake_launch_modules()
    saved = {k: sys.modules.get(k) for k in mods}
    sys.modules.update(mods)
    try:
        ns = runpy.run_path(str(path))
        entities = ns["generate_launch_description"]()
        args = {e.args[0]: e for e in entities if type(e).__name__ == "DeclareLaunchArgument"}
        context = {name: a.kwargs["default_value"] for name, a in args.items()}
        for k, v in overrides.items():
            assert k in args, f"{path.name}: no launch argument {k}"
            choices = args[k].kwargs.get("choices")
            assert choices is None or v in choices
            context[k] = v
        nodes = []
        for e in entities:
            if type(e).__name__ == "OpaqueFunction":
                nodes.extend(e.kwargs["function"](context))
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
    return nodes


def _declared_params(pkg: str, module: str) -> set[str]:
    """Names passed as a constant to ``declare_parameter`` in a node module."""
    tree = ast.parse((SRC / pkg / pkg / "nodes" / f"{module}.py").read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "declare_parameter"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            out.add(node.args[0].value)
    return out


def _declared_param_types(pkg: str, module: str) -> dict[str, type]:
    """``declare_parameter(name, <constant default>)`` -> {name: type of the default}."""
    tree = ast.parse((SRC / pkg / pkg / "nodes" / f"{module}.py").read_text(encoding="utf-8"))
    out: dict[str, type] = {}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "declare_parameter"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            default = node.args[1] if len(node.args) > 1 else None
            out[node.args[0].value] = (
                type(default.value) if isinstance(default, ast.Constant) else str
            )
    return out


def _node_param_types(package: str, executable: str) -> dict[str, type]:
    """Every parameter a node declares, with its type (dataclass-declared ones included)."""
    from pneu_control.controller.params import AxisControllerParams
    from pneu_msgs_py.params.core import describe
    from pneu_sim.nodes.sim_core import SimNodeParams

    base = {"use_sim_time": bool, "executor": str}  # executor: declared by run_node, every node
    if (package, executable) == ("pneu_sim", "sim_node"):
        return base | {s.name: s.type for s in describe(SimNodeParams)}
    if package == "pneu_control" and executable.endswith("_controller"):
        own = dict.fromkeys(_declared_params("pneu_control", "controller_node"), str)
        own["state_rate_hz"] = float
        return base | own | {s.name: s.type for s in describe(AxisControllerParams)}
    if (package, executable) == ("pneu_control", "controller_manager"):
        return base | dict.fromkeys(_declared_params(package, executable), str)
    if (package, executable) == ("pneu_control", "exciter"):
        return base | _declared_param_types(package, "exciter_node")
    if (package, executable) == ("pneu_control", "task_runner"):
        return base | _declared_param_types(package, "task_node")
    module = {"logger": "logger_node", "driver_node": "driver_node"}[executable]
    return base | dict.fromkeys(_declared_params(package, module), str)


def _check_values(where: str, declared: dict[str, type], values: dict) -> None:
    for key, value in values.items():
        assert key in declared, f"{where} declares no parameter {key}"
        want = declared[key]
        if want is float:
            assert isinstance(value, float), f"{where}: {key}={value!r} must be a float"
        elif want in (int, bool):
            assert type(value) is want, (where, key, value)
        if isinstance(value, str) and value.endswith(".yaml"):
            assert Path(value).is_file(), f"{where}: {key} -> missing {value}"


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


_TASK = str(ROOT / "config" / "tasks" / "coupling_insert_lock.yaml")
_OVERRIDES = {
    "excite.launch.py": [{}, {"target": "rig", "axes": "linear", "level": "quick"}],
    "task.launch.py": [
        {"task": _TASK},
        {"task": _TASK, "target": "rig", "plumbing": "bidirectional", "executor": "single"},
    ],
}
_DEFAULT_OVERRIDES = [
    {},
    {"controller": "pid", "axes": "linear", "reference": "sine:amplitude=20,frequency_hz=0.25"},
    {"recorder": "rosbag2", "executor": "single", "state_rate_hz": "50"},
    {"deployment": "hosted", "mode": "realtime", "axes": "both"},
]
LAUNCH_CASES = [
    (path, ov) for path in LAUNCH_FILES for ov in _OVERRIDES.get(path.name, _DEFAULT_OVERRIDES)
]


@pytest.mark.parametrize(
    ("path", "overrides"),
    LAUNCH_CASES,
    ids=[f"{p.parent.parent.name}/{p.name}:{i}" for i, (p, _) in enumerate(LAUNCH_CASES)],
)
def test_launch_files_start_existing_executables_with_valid_parameters(path, overrides, tmp_path):
    args_of = {p: _launch_args(p) for p in LAUNCH_FILES}
    overrides = {k: v for k, v in overrides.items() if k in args_of[path]}  # rig: no mode
    overrides["out"] = str(tmp_path / "run")
    actions = _run_launch(path, overrides)
    nodes = [a for a in actions if type(a).__name__ == "Node"]
    assert nodes, f"{path.name} starts no node"
    scripts = {pkg: _console_scripts(pkg) for pkg in PACKAGES}
    names = [n.kwargs.get("name") for n in nodes if "name" in n.kwargs]
    assert len(names) == len(set(names))
    assert "logger" in names
    # what answers the samples: the controllers (their own processes, or hosted), or the
    # excitation experiment
    hosted = overrides.get("deployment") == "hosted"
    assert hosted or any(n.endswith("_controller") or n == "pneu_exciter" for n in names)
    for n in nodes:
        pkg, exe = n.kwargs["package"], n.kwargs["executable"]
        assert exe in scripts.get(pkg, {}), f"{path.name}: {pkg} has no executable {exe}"
        for entry in n.kwargs.get("parameters", []):
            if isinstance(entry, dict):
                _check_values(f"{path.name}: {exe}", _node_param_types(pkg, exe), entry)
                continue
            f = Path(entry)  # a params file: its sections must be nodes of this process
            assert f.is_file(), f"{path.name}: parameter file {entry} missing"
            data = yaml.safe_load(f.read_text(encoding="utf-8"))
            if exe == "controller_manager":
                in_process = {
                    "controller_manager": ("pneu_control", "controller_manager"),
                    "pneu_sim": ("pneu_sim", "sim_node"),
                    "pneu_driver": ("pneu_driver", "driver_node"),
                    "linear_controller": ("pneu_control", "linear_controller"),
                    "rotary_controller": ("pneu_control", "rotary_controller"),
                }
                for section, body in data.items():
                    assert section in in_process, f"{f.name}: section {section}"
                    _check_values(
                        f"{path.name}: {section}",
                        _node_param_types(*in_process[section]),
                        _flatten(body["ros__parameters"]),
                    )
            else:
                assert f.parent.name == "config" and f.parent.parent.name in PACKAGES
                assert n.kwargs["name"] in data, f"{f.name} has no section {n.kwargs['name']}"
    if overrides.get("axes") == "linear":
        assert "rotary_controller" not in names
    recorders = [a for a in actions if type(a).__name__ == "ExecuteProcess"]
    realtime = overrides.get("mode", "realtime" if "mode" not in args_of[path] else "lockstep")
    if overrides.get("recorder") == "rosbag2" or realtime == "realtime":
        (rec,) = recorders
        cmd = rec.kwargs["cmd"]
        if cmd[0] != "ros2":  # at SCHED_FIFO below the control path (realtime, privileged)
            assert cmd[1:3] == ["-m", "pneu_msgs_py.lifecycle.realtime"] and cmd[4] == "--"
            assert 0 < int(cmd[3]) < 49
            cmd = cmd[5:]
        assert cmd[:6] == ["ros2", "bag", "record", "-s", "mcap", "-o"]
        assert cmd[6] == str(tmp_path / "run" / "bag")
        qos = yaml.safe_load(Path(cmd[cmd.index("--qos-profile-overrides-path") + 1]).read_text())
        topics = cmd[cmd.index("--topics") + 1 :]
        assert sorted(qos) == sorted(topics) and "/pneu/linear/joint_state" in topics
        logger = next(n for n in nodes if n.kwargs.get("name") == "logger")
        assert logger.kwargs["parameters"][0]["recorder"] == "rosbag2"
    else:
        assert not recorders


def _launch_args(path: Path) -> set[str]:
    mods = _fake_launch_modules()
    saved = {k: sys.modules.get(k) for k in mods}
    sys.modules.update(mods)
    try:
        entities = runpy.run_path(str(path))["generate_launch_description"]()
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
    return {e.args[0] for e in entities if type(e).__name__ == "DeclareLaunchArgument"}


def test_a_launch_never_overwrites_a_run(tmp_path):
    path = SRC / "pneu_sim" / "launch" / "sim.launch.py"
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.mcap").write_bytes(b"an earlier run")
    with pytest.raises(RuntimeError, match="run.mcap exists; choose another out"):
        _run_launch(path, {"out": str(tmp_path / "run")})


def test_hosted_deployment_needs_realtime(tmp_path):
    path = SRC / "pneu_sim" / "launch" / "sim.launch.py"
    with pytest.raises(RuntimeError, match="mode:=realtime"):
        _run_launch(path, {"deployment": "hosted", "out": str(tmp_path)})


def test_sim_launch_waits_for_its_subscribers_and_ends_the_launch(tmp_path):
    path = SRC / "pneu_sim" / "launch" / "sim.launch.py"
    for axes, n_ctrl in (("both", 2), ("linear", 1)):
        nodes = _run_launch(path, {"axes": axes, "out": str(tmp_path / axes)})
        sim = next(n for n in nodes if n.kwargs.get("executable") == "sim_node")
        params = sim.kwargs["parameters"][0]
        assert params["startup.min_subscribers"] == 1  # every sensor topic recorded, at least
        assert sim.kwargs["on_exit"], "the run must end the launch when the sim finishes"
        ctrl = [n for n in nodes if n.kwargs.get("name", "").endswith("_controller")]
        assert len(ctrl) == n_ctrl
        for c in ctrl:
            over = c.kwargs["parameters"][1]
            assert over["use_sim_time"] is True and over["mode"] == "lockstep"


def test_reference_argument_becomes_typed_reference_parameters(tmp_path):
    path = SRC / "pneu_sim" / "launch" / "sim.launch.py"
    nodes = _run_launch(
        path,
        {
            "reference": "sine:amplitude=20,frequency_hz=0.25",
            "rotary_reference": "constant:value=800",
            "out": str(tmp_path),
        },
    )
    by = {
        n.kwargs["name"]: n.kwargs["parameters"][1]
        for n in nodes
        if n.kwargs.get("name", "").endswith("_controller")
    }
    assert by["linear_controller"]["reference.amplitude"] == 20.0
    assert isinstance(by["linear_controller"]["reference.amplitude"], float)
    assert by["rotary_controller"]["reference.kind"] == "constant"
    assert by["rotary_controller"]["reference.value"] == 800.0


def test_param_types_helper_sees_dataclass_fields():
    types_ = _node_param_types("pneu_control", "linear_controller")
    assert types_["eso_smc.epsilon"] is float and "controllers_file" in types_
    assert dataclasses.is_dataclass(
        __import__("pneu_sim.nodes.sim_core").nodes.sim_core.SimNodeParams
    )


def _env_actions(entities) -> dict[str, str]:
    return {e.args[0]: e.args[1] for e in entities if type(e).__name__ == "SetEnvironmentVariable"}


def test_launches_are_secured_by_a_keystore_or_say_so(tmp_path, monkeypatch, capsys):
    """keystore:= enables enforced SROS2 for every process; unsecured, the twin discovers on
    localhost only and the rig warns in one line; a keystore without the graph's enclaves
    is refused before anything starts."""
    from pneu_msgs_py.contract.security import ROLES, enclave

    sim = SRC / "pneu_sim" / "launch" / "sim.launch.py"
    rig = SRC / "pneu_driver" / "launch" / "rig.launch.py"
    for var in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_SECURITY_ENABLE"):
        monkeypatch.delenv(var, raising=False)
    env = _env_actions(_run_launch(sim, {"out": str(tmp_path / "a")}))
    assert env == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    capsys.readouterr()
    assert _env_actions(_run_launch(rig, {"out": str(tmp_path / "b")})) == {}
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unsecured" in err[0] and "keystore:=" in err[0]
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    _run_launch(rig, {"out": str(tmp_path / "c")})
    assert capsys.readouterr().err == ""  # localhost-only: nothing to warn of
    keys = tmp_path / "keys"
    with pytest.raises(RuntimeError, match="keystore: .* refused; allowed: a keystore made by"):
        _run_launch(rig, {"out": str(tmp_path / "d"), "keystore": str(keys)})
    for r in ROLES:
        d = keys / "enclaves" / enclave(r).lstrip("/")
        d.mkdir(parents=True)
        (d / "permissions.p7s").write_text("signed")
    entities = _run_launch(rig, {"out": str(tmp_path / "e"), "keystore": str(keys)})
    assert _env_actions(entities) == {
        "ROS_SECURITY_KEYSTORE": str(keys),
        "ROS_SECURITY_ENABLE": "true",
        "ROS_SECURITY_STRATEGY": "Enforce",
    }
    for path in LAUNCH_FILES:
        assert "keystore" in _launch_args(path), path.name
