"""The shipped Foxglove and PlotJuggler layouts name only what a `pneu run` bag holds.

A bag is written by the ``pneu`` command line (both axes, a short controller
silence so the supervisor writes ``/diagnostics``), read back with the
independent reader ``mcap_ros2``; every layout file in ``config/layouts/`` is
parsed on its own (json, ElementTree) and each topic path and field it names
is resolved in the decoded messages. For PlotJuggler the series names are
built from the decoded messages the way its ROS 2 parsers name them
(JointState by joint name, other messages by field path).
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pneu_control.analysis.layouts import KINDS, layout_files
from pneu_control.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
LAYOUTS = ROOT / "config" / "layouts"
FOXGLOVE = sorted(LAYOUTS.glob("foxglove_*.json"))
PLOTJUGGLER = sorted(LAYOUTS.glob("plotjuggler_*.xml"))
PANEL_TYPES = {"Plot", "DiagnosticSummary", "DiagnosticStatusPanel", "Tab"}
# what the issue asks each layout to show, per axis: controller-state names + topics
WANTED_STATE = ("reference", "error", "u_raw", "z1", "z2", "z3", "s")
AXIS_OF = {"linear": "linear", "rotary": "rotary", "angle": "rotary"}  # a view's axis
# what each kind plots of the joints: (topic, joint, field)
JOINTS_SHOWN = {
    "linear": {("linear", "position")},
    "rotary": {("rotary", "velocity")},
    "both": {("linear", "position"), ("rotary", "velocity")},
    "angle": {("rotary", "position")},
    "task": {("linear", "position"), ("rotary", "position")},
}


@pytest.fixture(scope="module")
def bag_messages(tmp_path_factory) -> dict[str, list]:
    """topic -> decoded messages of a bag written by ``pneu run``."""
    out = tmp_path_factory.mktemp("layout_run")
    rc = main(
        [
            "run",
            "--axis",
            "both",
            "--duration",
            "0.4",
            "--out",
            str(out),
            "--fault",
            "controller_silent:axis=linear,start_s=0.1,duration_s=0.05",
        ]
    )
    assert rc == 3  # the supervisor took the silenced axis safe (a diagnostics event to show)
    msgs: dict[str, list] = {}
    with open(out / "run.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            msgs.setdefault(channel.topic, []).append(msg)
    assert "/diagnostics" in msgs  # the watchdog trip
    return msgs


def test_shipped_layouts_are_the_generated_ones():
    files = layout_files()
    assert sorted(files) == sorted(p.name for p in FOXGLOVE + PLOTJUGGLER)
    for name, text in files.items():
        assert (LAYOUTS / name).read_text(encoding="utf-8") == text, (
            f"config/layouts/{name} is stale: python -m pneu_control.analysis.layouts"
        )
    assert {p.stem.split("_", 1)[1] for p in FOXGLOVE} == set(KINDS)


# -- Foxglove ------------------------------------------------------------------

_PATH = re.compile(r"^(?P<topic>/[\w/]+)\.(?P<field>\w+)(?:\[(?P<index>\d+)\])?$")


def _leaves(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert set(node) >= {"first", "second", "direction"}, node
    assert node["direction"] in ("row", "column")
    assert 0 < node.get("splitPercentage", 50) < 100
    return _leaves(node["first"]) + _leaves(node["second"])


def _panels(doc: dict) -> list[str]:
    """Every panel id the layout shows (through Tab panels)."""
    out = []
    for pid in _leaves(doc["layout"]):
        out.append(pid)
        if pid.startswith("Tab!"):
            for tab in doc["configById"][pid]["tabs"]:
                out.extend(_leaves(tab["layout"]))
    return out


@pytest.mark.parametrize("path", FOXGLOVE, ids=lambda p: p.name)
def test_foxglove_layout_resolves_in_a_pneu_run_bag(path, bag_messages):
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert set(doc) == {"configById", "globalVariables", "userNodes", "playbackConfig", "layout"}
    shown = _panels(doc)
    assert len(shown) == len(set(shown)) and set(shown) == set(doc["configById"])
    seen: set[tuple[str, str]] = set()  # (topic, joint name or field)
    for pid in shown:
        ptype = pid.split("!")[0]
        assert ptype in PANEL_TYPES, pid
        cfg = doc["configById"][pid]
        if ptype.startswith("Diagnostic"):
            assert cfg["topicToRender"] in bag_messages
            seen.add((cfg["topicToRender"], "status"))
        if ptype != "Plot":
            continue
        assert cfg["xAxisVal"] == "timestamp" and cfg["paths"]
        for p in cfg["paths"]:
            m = _PATH.match(p["value"])
            assert m, p["value"]
            assert p["timestampMethod"] == "receiveTime"
            topic, field = m["topic"], m["field"]
            assert topic in bag_messages, f"{path.name}: {topic} not in the bag"
            msg = bag_messages[topic][-1]
            value = getattr(msg, field)  # AttributeError: no such field
            if m["index"] is not None:
                i = int(m["index"])
                assert i < len(value), f"{p['value']}: {len(value)} values"
                value = value[i]
                # a JointState array is read by position: the index must be the joint named
                assert msg.name[i] in p["label"], (p["value"], msg.name, p["label"])
                seen.add((topic, msg.name[i]))
            else:
                seen.add((topic, field))
            assert isinstance(value, float)
    kind = path.stem.split("_", 1)[1]
    for axis in (AXIS_OF[v] for v in KINDS[kind]):
        for name in WANTED_STATE:
            assert (f"/pneu/{axis}/controller_state", name) in seen, (axis, name)
        assert (f"/pneu/{axis}/valve_command", f"{axis}_valve") in seen
    pressures = {t for t, f in seen if t.startswith("/pneu/pressure/")}
    cyl = {"/pneu/pressure/cylinder_1", "/pneu/pressure/cylinder_2"}
    motor = {"/pneu/pressure/motor_in"}
    want = {
        "linear": cyl,
        "rotary": motor,
        "both": cyl | motor,
        "angle": motor,
        "task": cyl | motor,
    }
    assert pressures == want[kind]
    joints = {(j, p["value"].split(".")[1].split("[")[0]) for j in ("linear", "rotary") for p in [
        q for pid in shown if pid.startswith("Plot!") for q in doc["configById"][pid]["paths"]
        if q["value"].startswith(f"/pneu/{j}/joint_state.")
    ]}  # fmt: skip
    assert joints == JOINTS_SHOWN[kind]
    assert ("/diagnostics", "status") in seen


# -- PlotJuggler ---------------------------------------------------------------


def _pj_series(topic: str, msg) -> set[str]:
    """Numeric series PlotJuggler's ROS 2 parsers make of one message (ros_parser.cpp)."""
    out = {f"{topic}/header/stamp/sec", f"{topic}/header/stamp/nanosec"}
    if hasattr(msg, "name") and hasattr(msg, "effort"):  # sensor_msgs/JointState
        for key in ("position", "velocity", "effort"):
            arr = getattr(msg, key)
            for i in range(min(len(msg.name), len(arr))):
                out.add(f"{topic}/{msg.name[i]}/{key}")
    elif hasattr(msg, "fluid_pressure"):
        out |= {f"{topic}/fluid_pressure", f"{topic}/variance"}
    return out


def _check_splitter(el: ET.Element) -> list[ET.Element]:
    children = [c for c in el if c.tag in ("DockSplitter", "DockArea")]
    assert el.get("orientation") in ("-", "|")
    assert int(el.get("count")) == len(children)
    sizes = [float(x) for x in el.get("sizes").split(";")]
    assert len(sizes) == len(children) and abs(sum(sizes) - 1.0) < 1e-3
    areas = []
    for c in children:
        areas.extend(_check_splitter(c) if c.tag == "DockSplitter" else [c])
    return areas


@pytest.mark.parametrize("path", PLOTJUGGLER, ids=lambda p: p.name)
def test_plotjuggler_layout_resolves_in_a_pneu_run_bag(path, bag_messages):
    root = ET.parse(path).getroot()
    (tabs,) = root.findall("tabbed_widget")
    assert tabs.get("name") == "Main Window" and tabs.get("parent") == "main_window"
    series = set()
    for topic, msgs in bag_messages.items():
        for msg in msgs[-3:]:
            series |= _pj_series(topic, msg)
    kind = path.stem.split("_", 1)[1]
    assert [t.get("tab_name") for t in tabs.findall("Tab")] == list(KINDS[kind])
    named = set()
    for tab in tabs.findall("Tab"):
        (container,) = tab.findall("Container")
        (top,) = container.findall("DockSplitter")
        areas = _check_splitter(top)
        assert len({a.get("name") for a in areas}) == len(areas)
        for area in areas:
            (plot,) = area.findall("plot")
            assert plot.get("mode") == "TimeSeries"
            for curve in plot.findall("curve"):
                name = curve.get("name")
                assert name in series, f"{path.name}: no series {name} in the bag"
                assert re.fullmatch(r"#[0-9a-f]{6}", curve.get("color"))
                named.add(name)
    for axis in (AXIS_OF[v] for v in KINDS[kind]):
        for name in WANTED_STATE:
            assert f"/pneu/{axis}/controller_state/{name}/position" in named
        assert f"/pneu/{axis}/valve_command/{axis}_valve/effort" in named
    shown = {
        (j, f)
        for j in ("linear", "rotary")
        for f in ("position", "velocity")
        if f"/pneu/{j}/joint_state/{j}/{f}" in named
    }
    assert shown == JOINTS_SHOWN[kind]
