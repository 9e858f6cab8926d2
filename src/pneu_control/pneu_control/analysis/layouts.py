"""Viewer layouts for a run: Foxglove (JSON) and PlotJuggler (XML), one per experiment kind.

A run's bag (or the live view, ``pneu run --live``) opens in Foxglove and
PlotJuggler; these layouts show it as the paper does: reference against
measured, the error, the valve voltage, the chamber pressures, the observer
states and (Foxglove) the diagnostics. Kinds: ``linear`` (position tracking:
sine, smooth step), ``rotary`` (constant speed), ``both``, ``angle`` (rotary angle
positioning, ``rotary_control: angle``: the encoder angle θ against its reference)
and ``task`` (a task or a joint trajectory: the rod's position and the angle). The files ship in
``config/layouts/`` (installed to ``share/<pkg>/config/layouts/``) and are
generated here from the topic table, so they always name topics and joint
names the bag has (``python -m pneu_control.analysis.layouts [DIR]``
rewrites them; a test checks the shipped files are this output and that every
path resolves in a bag written by ``pneu run``).

Values are SI as on the topics (m, rad/s, Pa absolute, V): neither viewer can
scale a series from a layout file without a script.

How each viewer names a value:

- Foxglove message paths index arrays: ``/pneu/linear/joint_state.position[0]``;
  controller-state values by their index in the ``name`` array
  (:data:`~pneu_msgs_py.contract.topics.DEFAULT_STATE_FIELDS`).
- PlotJuggler's JointState parser names a value by its joint name:
  ``/pneu/linear/joint_state/linear/position``,
  ``/pneu/linear/controller_state/reference/position``; other messages by
  field path (``/pneu/pressure/cylinder_1/fluid_pressure``). Its MCAP loader
  puts the samples at the record's publish time (= log time = the sample
  stamp in our bags). Diagnostics are not plotted: PlotJuggler names a status
  series by hardware id and status name, which exist only for the supervisor
  transitions that happened (they appear in its tree under ``/diagnostics``).
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from pneu_msgs_py.contract.topics import (
    CONTROLLER_STATE_TOPIC,
    DEFAULT_STATE_FIELDS,
    DIAGNOSTICS_TOPIC,
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    ROTARY_COUNTS_JOINT,
    VALVE_COMMAND_TOPIC,
    valve_joint,
)

__all__ = [
    "KINDS",
    "Curve",
    "Plot",
    "foxglove_layout",
    "layout_files",
    "plots_for",
    "plotjuggler_layout",
    "write_layouts",
]

#: kind -> its views (a tab each): ``linear`` (x), ``rotary`` (ω) or ``angle`` (θ)
KINDS: dict[str, tuple[str, ...]] = {
    "linear": ("linear",),
    "rotary": ("rotary",),
    "both": ("linear", "rotary"),
    "angle": ("angle",),
    "task": ("linear", "angle"),
}
_AXIS_OF_VIEW = {"linear": "linear", "rotary": "rotary", "angle": "rotary"}

#: JointState topics -> their ``name`` array (the contract: topics.py, wire.py)
JOINT_NAMES: dict[str, tuple[str, ...]] = {
    JOINT_STATE_TOPIC["linear"]: ("linear",),
    JOINT_STATE_TOPIC["rotary"]: ("rotary", ROTARY_COUNTS_JOINT),
    **{VALVE_COMMAND_TOPIC[a]: (valve_joint(a),) for a in ("linear", "rotary")},
    **{CONTROLLER_STATE_TOPIC[a]: DEFAULT_STATE_FIELDS for a in ("linear", "rotary")},
}
_PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b")


@dataclass(frozen=True)
class Curve:
    """One plotted value: ``field`` of ``topic``, of joint ``joint`` for a JointState."""

    topic: str
    field: str
    label: str
    joint: str | None = None

    def foxglove_path(self) -> str:
        """The curve as a Foxglove message path (``topic.field[index]`` for a joint)."""
        if self.joint is None:
            return f"{self.topic}.{self.field}"
        return f"{self.topic}.{self.field}[{JOINT_NAMES[self.topic].index(self.joint)}]"

    def plotjuggler_name(self) -> str:
        """The curve's series name in PlotJuggler (``topic/joint/field``)."""
        if self.joint is None:
            return f"{self.topic}/{self.field}"
        return f"{self.topic}/{self.joint}/{self.field}"


@dataclass(frozen=True)
class Plot:
    """One panel of a layout: a title and the curves drawn in it."""

    key: str  # unique within a layout: panel ids, dock names
    title: str
    curves: tuple[Curve, ...]


def _state(axis: str, name: str, label: str | None = None) -> Curve:
    return Curve(CONTROLLER_STATE_TOPIC[axis], "position", label or name, name)


def plots_for(view: str) -> tuple[tuple[Plot, ...], tuple[Plot, ...]]:
    """(signal plots, observer plots) of one view: ``linear``, ``rotary`` (speed) or
    ``angle`` (the rotary axis under ``rotary_control: angle``)."""
    axis = _AXIS_OF_VIEW[view]
    if view == "linear":
        meas = Curve(
            JOINT_STATE_TOPIC["linear"], "position", "measured: linear (laser x)", "linear"
        )
        what, unit, dunit, ddunit = "position", "m", "m/s", "m/s²"
        chambers = [t for t, (attr, _) in PRESSURE_TOPICS.items() if attr in ("p_c1", "p_c2")]
        where = "cylinder chamber"
    elif view == "angle":
        meas = Curve(
            JOINT_STATE_TOPIC["rotary"], "position", "measured: rotary angle (encoder θ)", "rotary"
        )
        what, unit, dunit, ddunit = "angle", "rad", "rad/s", "rad/s²"
        chambers = [t for t, (attr, _) in PRESSURE_TOPICS.items() if attr == "p_m1"]
        where = "motor inlet"
    else:
        meas = Curve(
            JOINT_STATE_TOPIC["rotary"], "velocity", "measured: rotary (encoder ω)", "rotary"
        )
        what, unit, dunit, ddunit = "speed", "rad/s", "rad/s²", "rad/s³"
        chambers = [t for t, (attr, _) in PRESSURE_TOPICS.items() if attr == "p_m1"]
        where = "motor inlet"
    key = view  # panel keys unique within a layout
    pressures = tuple(
        Curve(t, "fluid_pressure", PRESSURE_TOPICS[t][1].replace("_", " ")) for t in chambers
    )
    valve = Curve(
        VALVE_COMMAND_TOPIC[axis], "effort", f"{valve_joint(axis)} (command)", valve_joint(axis)
    )
    signals = (
        Plot(
            f"{key}_{what}",
            f"{axis} {what}: reference vs measured [{unit}]",
            (_state(axis, "reference"), meas),
        ),
        Plot(f"{key}_error", f"{axis} error e = r − y [{unit}]", (_state(axis, "error"),)),
        Plot(
            f"{key}_valve",
            f"{axis} valve voltage [V] (5 V = closed)",
            (valve, _state(axis, "u_raw", "u_raw (before saturation)")),
        ),
        Plot(f"{key}_pressure", f"{axis} {where} pressure [Pa abs]", pressures),
    )
    observers = (
        Plot(
            f"{key}_z1",
            f"{axis} observer z1 vs measured [{unit}]",
            (_state(axis, "z1"), _state(axis, "measured")),
        ),
        Plot(f"{key}_z2", f"{axis} observer z2 [{dunit}]", (_state(axis, "z2"),)),
        Plot(
            f"{key}_z3", f"{axis} observer z3, total disturbance [{ddunit}]", (_state(axis, "z3"),)
        ),
        Plot(f"{key}_s", f"{axis} sliding variable s [{dunit}]", (_state(axis, "s"),)),
    )
    return signals, observers


# -- Foxglove ------------------------------------------------------------------


def _fg_plot(plot: Plot) -> dict:
    return {
        "foxglovePanelTitle": plot.title,
        "paths": [
            {
                "value": c.foxglove_path(),
                "enabled": True,
                "timestampMethod": "receiveTime",
                "label": c.label,
                "color": _PALETTE[i % len(_PALETTE)],
            }
            for i, c in enumerate(plot.curves)
        ],
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "showLegend": True,
        "legendDisplay": "floating",
        "showPlotValuesInLegend": False,
        "isSynced": True,
        "xAxisVal": "timestamp",
        "sidebarDimension": 240,
    }


def _stack(ids: list, direction: str) -> str | dict:
    """Panels side by side (``row``) or stacked (``column``), equal shares."""
    if len(ids) == 1:
        return ids[0]
    return {
        "direction": direction,
        "first": ids[0],
        "second": _stack(ids[1:], direction),
        "splitPercentage": round(100.0 / len(ids), 2),
    }


def _fg_axis(axis: str, config: dict) -> dict:
    signals, observers = plots_for(axis)
    cols = []
    for group in (signals, observers):
        ids = []
        for p in group:
            config[f"Plot!{p.key}"] = _fg_plot(p)
            ids.append(f"Plot!{p.key}")
        cols.append(_stack(ids, "column"))
    summary, detail = f"DiagnosticSummary!{axis}", f"DiagnosticStatusPanel!{axis}"
    config[summary] = {
        "foxglovePanelTitle": "diagnostics (safety supervisor)",
        "topicToRender": DIAGNOSTICS_TOPIC,
        "minLevel": 0,
        "pinnedIds": [],
        "hardwareIdFilter": "",
        "sortByLevel": True,
    }
    config[detail] = {
        "foxglovePanelTitle": "diagnostics: detail",
        "topicToRender": DIAGNOSTICS_TOPIC,
        "selectedHardwareId": "",
        "selectedName": "",
    }
    return {
        "direction": "row",
        "first": cols[0],
        "second": {
            "direction": "row",
            "first": cols[1],
            "second": _stack([summary, detail], "column"),
            "splitPercentage": 62,
        },
        "splitPercentage": 50,
    }


def foxglove_layout(kind: str) -> dict:
    """The layout as Foxglove's "Layouts > Import from file..." reads it (its export format)."""
    config: dict[str, dict] = {}
    axes = KINDS[kind]
    if len(axes) == 1:
        root: str | dict = _fg_axis(axes[0], config)
    else:
        root = "Tab!axes"
        config[root] = {
            "activeTabIdx": 0,
            "tabs": [{"title": a, "layout": _fg_axis(a, config)} for a in axes],
        }
    return {
        "configById": config,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": root,
    }


# -- PlotJuggler ---------------------------------------------------------------


def _pj_dock(parent: ET.Element, plot: Plot) -> None:
    area = ET.SubElement(parent, "DockArea", name=plot.title)
    p = ET.SubElement(
        area, "plot", mode="TimeSeries", flip_x="false", flip_y="false", style="Lines"
    )
    for i, c in enumerate(plot.curves):
        ET.SubElement(p, "curve", name=c.plotjuggler_name(), color=_PALETTE[i % len(_PALETTE)])


def _pj_column(parent: ET.Element, plots: tuple[Plot, ...]) -> None:
    split = ET.SubElement(
        parent,
        "DockSplitter",
        orientation="-",
        count=str(len(plots)),
        sizes=";".join([f"{1.0 / len(plots):.6g}"] * len(plots)),
    )
    for p in plots:
        _pj_dock(split, p)


def plotjuggler_layout(kind: str) -> str:
    """The layout XML (PlotJuggler: File > Load layout, or ``-l FILE``), a tab per axis."""
    root = ET.Element("root")
    tabs = ET.SubElement(root, "tabbed_widget", name="Main Window", parent="main_window")
    for axis in KINDS[kind]:
        signals, observers = plots_for(axis)
        tab = ET.SubElement(tabs, "Tab", tab_name=axis, containers="1")
        container = ET.SubElement(tab, "Container")
        row = ET.SubElement(
            container, "DockSplitter", orientation="|", count="2", sizes="0.55;0.45"
        )
        _pj_column(row, signals)
        _pj_column(row, observers)
    ET.SubElement(tabs, "currentTabIndex", index="0")
    ET.SubElement(root, "use_relative_time_offset", enabled="1")
    ET.indent(root, space=" ")
    return "<?xml version='1.0' encoding='UTF-8'?>\n" + ET.tostring(root, encoding="unicode") + "\n"


# -- files ---------------------------------------------------------------------


def layout_files() -> dict[str, str]:
    """File name -> text of every shipped layout."""
    out = {}
    for kind in KINDS:
        out[f"foxglove_{kind}.json"] = (
            json.dumps(foxglove_layout(kind), indent=2, ensure_ascii=False) + "\n"
        )
        out[f"plotjuggler_{kind}.xml"] = plotjuggler_layout(kind)
    return out


def write_layouts(directory: str | Path) -> list[Path]:
    """Write every layout into ``directory`` (created); returns the paths."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, text in layout_files().items():
        (d / name).write_text(text, encoding="utf-8")
        paths.append(d / name)
    return paths


if __name__ == "__main__":  # python -m pneu_control.analysis.layouts [DIR]
    from pneu_msgs_py.params.paths import config_dir

    target = Path(sys.argv[1]) if len(sys.argv) > 1 else config_dir() / "layouts"
    for path in write_layouts(target):
        print(f"wrote {path}")
