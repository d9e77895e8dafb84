"""The Foxglove/Lichtblick layout of a configuration (`config/foxglove_layout.json` is this module's output for
the default configuration; a test holds them equal). ROS-free: JSON only.

Write one for your own constraints with

    python -m rta_attitude.recording.layout --config my.yaml my_layout.json

The margins are drawn one unit to a plot (a plot panel has one y axis), in SI units, as the bag holds them:

- pointing: every cone's h = theta - alpha (keep_out) or alpha - theta (keep_in), in rad, on one plot with a
  zero line, each cone a series. Not in deg: Lichtblick's time-series plots (1.10.8, checked in the app) apply
  only abs, sqrt, the trigonometric, log and rounding modifiers to a path, and ignore `.@rad2deg` without a
  word, so a plot titled in deg would show radians. Outside a windowed cone's windows h is +inf, written `inf`,
  which the apps read as no number: the series has a gap there;
- temperature: h = T_max - T [K]; battery: h = E - E_min [J]; each on a plot of its own with a zero line;
- body rates and wheel speeds: filter_status's h = v_max^2 - v^2 (rad^2/s^2) reads poorly, and the margin
  v_max - |v| needs arithmetic a message path has not. The bag has v itself (`state`, JointState positions), so
  the plots show each axis's v in rad/s between reference lines at -v_max and +v_max: the margin v_max - |v| is
  the gap to the nearer line.

Paths use the receive time (a bag's log time, which the recorder sets to the header stamp). Panel titles are
written under both apps' keys (`foxglovePanelTitle`, `lichtblickPanelTitle`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rta_attitude import topics
from rta_attitude.config.schema import AXIS_NAMES, Config
from rta_attitude.dynamics.state import OMEGA, PSI
from rta_attitude.errors import RtaError
from rta_attitude.files import write_text
from rta_attitude.recording.plots import target_label

TITLE_KEYS = ("foxglovePanelTitle", "lichtblickPanelTitle")
SERIES_COLORS = ("#4e98e2", "#f5774d", "#f7df71", "#5cd6a9", "#b077e0", "#e05c8a", "#8cd1ff", "#c9a26b")
LIMIT_COLOR = "#ff3333"
TIMESTAMP_METHOD = "receiveTime"
PLOT_OPTIONS: dict[str, Any] = {
    "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "left",
    "showPlotValuesInLegend": False, "isSynced": True, "xAxisVal": "timestamp", "followingViewWidth": 30,
}  # fmt: skip
"""The settings every plot panel shares. The legend sits left of the plot, as wide as its labels need
(`legend_width`), never over the lines (a floating legend covered half of a 1,600 x 1,000 window's small plots);
the values are read by hovering (the apps show them in the legend then)."""
LEGEND_CHAR_PX = 7.5
"""About how wide a legend label's character is in both apps (their UI font), px (measured in Lichtblick)."""
LEGEND_PAD_PX = 140
"""A legend row's colour swatch, its row actions and padding, px."""
POINTING_PLOT = "Plot!margins_pointing"
TEMPERATURE_PLOT = "Plot!margin_temperature"
BATTERY_PLOT = "Plot!margin_battery"
RATES_PLOT = "Plot!body_rates"
WHEELS_PLOT = "Plot!wheel_speeds"
MARGIN_PLOTS = (POINTING_PLOT, TEMPERATURE_PLOT, BATTERY_PLOT, RATES_PLOT, WHEELS_PLOT)
"""The margin plots, by panel id."""
TORQUE_PLOT = "Plot!torques"


def _titled(title: str, config: dict[str, Any]) -> dict[str, Any]:
    """A panel config with its title under both apps' keys."""
    return {**{k: title for k in TITLE_KEYS}, **config}


def number_text(value: float) -> str:
    """A reference line's value as the apps parse it: decimal, no exponent, at least 4 decimals and at least 4
    significant digits ('-1', '575.9587', '0.01745')."""
    decimals = max(4, 3 - math.floor(math.log10(abs(value)))) if value != 0.0 else 0
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _series(value: str, label: str, k: int) -> dict[str, Any]:
    return {"value": value, "enabled": True, "timestampMethod": TIMESTAMP_METHOD, "label": label,
            "color": SERIES_COLORS[k % len(SERIES_COLORS)]}


def _line(value: float, label: str) -> dict[str, Any]:
    """A reference line (a number as the path)."""
    return {"value": number_text(value), "enabled": True, "timestampMethod": TIMESTAMP_METHOD, "label": label,
            "color": LIMIT_COLOR}


def legend_width(paths: list[dict[str, Any]]) -> int:
    """The left legend's width for these series: its longest label, px."""
    return round(LEGEND_PAD_PX + LEGEND_CHAR_PX * max(len(p["label"]) for p in paths))


def _plot(title: str, paths: list[dict[str, Any]]) -> dict[str, Any]:
    return _titled(title, {"paths": paths, **PLOT_OPTIONS, "sidebarDimension": legend_width(paths)})


def status_path(namespace: str, entry: str, key: str | None = None) -> str:
    """The message path of a filter_status entry's message, or of one of its keys' value."""
    base = f'{namespace}/{topics.FILTER_STATUS}.status[:]{{name=="{entry}"}}'
    return f"{base}.message" if key is None else f'{base}.values[:]{{key=="{key}"}}.value'


def state_path(namespace: str, index: int) -> str:
    """The message path of one state component (`state`'s JointState position, STATE_NAMES order)."""
    return f"{namespace}/{topics.STATE}.position[{index}]"


def pointing_plot(cfg: Config, namespace: str) -> dict[str, Any]:
    """Every cone's margin h, in rad, with the zero line."""
    paths = [_series(status_path(namespace, topics.CONSTRAINT_STATUS_PREFIX + c.name, "h"),
                     f"{c.name} ({'<=' if c.kind == 'keep_in' else '>='} {math.degrees(c.half_angle_rad):g} deg, "
                     f"{target_label(c.target, c.target_vector)})", k)
             for k, c in enumerate(cfg.pointing)]
    return _plot("Pointing margins h [rad]: each cone's angle beyond its limit (> 0 safe)",
                 [*paths, _line(0.0, "h = 0 (limit)")])


def fixed_margin_plot(namespace: str, name: str, label: str, title: str) -> dict[str, Any]:
    """One constraint's h in model units (temperature [K], battery [J]) with the zero line."""
    return _plot(title, [_series(status_path(namespace, topics.CONSTRAINT_STATUS_PREFIX + name, "h"), label, 0),
                         _line(0.0, "limit")])


def speed_plot(namespace: str, title: str, prefix: str, first: int, limit: float, unit: str) -> dict[str, Any]:
    """Each axis's speed (state components first..first+2) between -limit and +limit."""
    paths = [_series(state_path(namespace, first + i), f"{prefix}_{a}", i) for i, a in enumerate(AXIS_NAMES)]
    bound = f"{number_text(limit)} {unit}"
    return _plot(f"{title} [{unit}]: margin = gap to +-{bound}", [*paths, _line(limit, "+max"), _line(-limit, "-max")])


def state_transitions(cfg: Config, namespace: str) -> dict[str, Any]:
    """The filter's status and fallback, and ok / intervening / violated of each cone, temperature, battery."""
    entries = [*(c.name for c in cfg.pointing), "temperature", "battery"]
    paths = [{"value": status_path(namespace, topics.QP_STATUS_NAME), "enabled": True,
              "timestampMethod": TIMESTAMP_METHOD, "label": "filter"},
             {"value": status_path(namespace, topics.QP_STATUS_NAME, topics.KEY_FALLBACK), "enabled": True,
              "timestampMethod": TIMESTAMP_METHOD, "label": "fallback"}]
    paths += [{"value": status_path(namespace, topics.CONSTRAINT_STATUS_PREFIX + n), "enabled": True,
               "timestampMethod": TIMESTAMP_METHOD, "label": n} for n in entries]
    return _titled("Filter status (pass / solved / fallback; per constraint ok / intervening / violated)",
                   {"isSynced": True, "showPoints": True, "xAxisRange": 30, "paths": paths})


def torque_plot(namespace: str) -> dict[str, Any]:
    """The desired and the filtered torque of each axis, on one plot (one unit)."""
    paths = []
    for i, axis in enumerate(AXIS_NAMES):
        paths.append(_series(f"{namespace}/{topics.TORQUE_DES}.vector.{axis}", f"u_des.{axis}", 2 * i))
        paths.append(_series(f"{namespace}/{topics.TORQUE_CMD}.vector.{axis}", f"u.{axis}", 2 * i + 1))
    return _plot("Torques: u_des (torque_des) vs filtered u (torque_cmd) [N m]", paths)


def diagnostics_summary(title: str, topic: str) -> dict[str, Any]:
    return _titled(title, {"topicToRender": topic, "minLevel": 0, "pinnedIds": [], "hardwareIdFilter": "",
                           "sortByLevel": True})


def attitude_panel(namespace: str) -> dict[str, Any]:
    """The 3D panel: the scene's markers and transform in the hill frame, with a grid."""
    return _titled("Attitude scene (hill frame): body, boresights, pointing cones about their targets", {
        "followTf": topics.HILL_FRAME, "followMode": "follow-none",
        "cameraState": {"distance": 7.5, "perspective": True, "phi": 60, "thetaOffset": 45, "target": [0, 0, 1.0],
                        "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "fovy": 45, "near": 0.01,
                        "far": 5000},
        "scene": {"enableStats": False}, "transforms": {},
        "topics": {f"{namespace}/{topics.SCENE_MARKERS}": {"visible": True},
                   f"{namespace}/{topics.SCENE_TRANSFORM}": {"visible": True},
                   f"{namespace}/{topics.ODOMETRY}": {"visible": False}},
        "layers": {"grid-hill": {"instanceId": "grid-hill", "layerId": "foxglove.Grid", "label": "Grid (hill)",
                                 "visible": True, "frameLocked": True, "frameId": topics.HILL_FRAME, "size": 20,
                                 "divisions": 20, "lineWidth": 1, "color": "#248eff66", "position": [0, 0, 0],
                                 "rotation": [0, 0, 0], "order": 1}},
        "publish": {"type": "point", "poseTopic": "/move_base_simple/goal", "pointTopic": "/clicked_point",
                    "poseEstimateTopic": "/initialpose", "poseEstimateXDeviation": 0.5,
                    "poseEstimateYDeviation": 0.5, "poseEstimateThetaDeviation": 0.26179939},
        "imageMode": {},
    })  # fmt: skip


def _split(direction: str, first: Any, second: Any, percent: float = 50) -> dict[str, Any]:
    return {"direction": direction, "first": first, "second": second, "splitPercentage": percent}


def tabs() -> dict[str, Any]:
    """The tabbed panel: the torques, the filter status and /diagnostics, the raw status."""
    return {"activeTabIdx": 0, "tabs": [
        {"title": "torques", "layout": TORQUE_PLOT},
        {"title": "status, /diagnostics",
         "layout": _split("row", "DiagnosticSummary!filter_status", "DiagnosticSummary!diagnostics")},
        {"title": "raw", "layout": _split("row", "RawMessages!filter_status",
                                          _split("column", "DiagnosticStatusPanel!filter_detail",
                                                 "DiagnosticSummary!run_status"))},
    ]}  # fmt: skip


def layout(cfg: Config, namespace: str = topics.DEFAULT_NAMESPACE) -> dict[str, Any]:
    """The layout (Foxglove's and Lichtblick's `LayoutData`) of a configuration's run under `namespace`."""
    ns = namespace.rstrip("/")
    L = cfg.limits
    status = f"{ns}/{topics.FILTER_STATUS}"
    config_by_id: dict[str, Any] = {
        POINTING_PLOT: pointing_plot(cfg, ns),
        TEMPERATURE_PLOT: fixed_margin_plot(ns, "temperature", "T_max - T",
                                            "Temperature margin T_max - T [K] (> 0 safe)"),
        BATTERY_PLOT: fixed_margin_plot(ns, "battery", "E - E_min", "Battery margin E - E_min [J] (> 0 safe)"),
        RATES_PLOT: speed_plot(ns, "Body rates", "omega", OMEGA.start, L.omega_max_rad_s, "rad/s"),
        WHEELS_PLOT: speed_plot(ns, "Wheel speeds", "psi", PSI.start, L.psi_max_rad_s, "rad/s"),
        TORQUE_PLOT: torque_plot(ns),
        "StateTransitions!filter_status": state_transitions(cfg, ns),
        "DiagnosticSummary!filter_status": diagnostics_summary("Filter status per constraint", status),
        "DiagnosticStatusPanel!filter_detail": _titled("Filter status detail",
                                                       {"topicToRender": status, "numericPrecision": 6}),
        "DiagnosticSummary!run_status": diagnostics_summary("Run status", f"{ns}/{topics.RUN_STATUS}"),
        "RawMessages!filter_status": {"topicPath": status, "diffEnabled": False, "diffMethod": "custom",
                                      "diffTopicPath": "", "showFullMessageForDiff": False, "expansion": "none"},
        "3D!attitude": attitude_panel(ns),
        "Tab!views": tabs(),
        "DiagnosticSummary!diagnostics": diagnostics_summary("/diagnostics (every node's summary)",
                                                             topics.DIAGNOSTICS),
    }  # fmt: skip
    # proportions for a 1,600 x 1,000 window (checked in Lichtblick, docs/foxglove.md): the status panel draws 64
    # px a row (filter, fallback, each cone, temperature, battery): the paper's 6 rows take 55 % of the right column
    margins = _split("column", POINTING_PLOT, _split("column", _split("row", TEMPERATURE_PLOT, BATTERY_PLOT),
                                                     _split("column", _split("row", RATES_PLOT, WHEELS_PLOT),
                                                            "Tab!views", 45), 30), 25)
    views = _split("column", "3D!attitude", "StateTransitions!filter_status", 45)
    return {"configById": config_by_id, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": _split("row", margins, views, 50)}


def layout_json(cfg: Config, namespace: str = topics.DEFAULT_NAMESPACE) -> str:
    """`layout` as the JSON text the shipped file holds (2-space indent, a final newline)."""
    return json.dumps(layout(cfg, namespace), indent=2) + "\n"


def write_layout(cfg: Config, path: str | Path, namespace: str = topics.DEFAULT_NAMESPACE) -> Path:
    """Write `layout_json` to path (atomically: never a half-written file).

    Raises:
        OutputError: it could not be written.
    """
    return write_text(Path(path), layout_json(cfg, namespace))


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m rta_attitude.recording.layout [--config YAML] [--namespace NS] OUT`."""
    from rta_attitude import config

    parser = argparse.ArgumentParser(prog="python -m rta_attitude.recording.layout",
                                     description="write the Foxglove/Lichtblick layout of a configuration")
    parser.add_argument("out", type=Path, help="the layout JSON to write")
    parser.add_argument("--config", type=Path, default=None, help="parameter file (default: the package's)")
    parser.add_argument("--namespace", default=topics.DEFAULT_NAMESPACE, help="the run's namespace (default /rta)")
    args = parser.parse_args(argv)
    try:
        print(f"layout: {write_layout(config.load(args.config), args.out, args.namespace)}")
    except RtaError as exc:
        print(f"ERROR: {exc}", file=sys.stderr)
        return 1
    return 0


__all__ = ["MARGIN_PLOTS", "TITLE_KEYS", "layout", "layout_json", "main", "number_text", "state_path", "status_path",
           "write_layout"]

if __name__ == "__main__":
    raise SystemExit(main())
