"""The calibrator's result messages (msgs_doc/calibrator.md, "Results"): `~/residuals` and
`~/markers` of a calibration, built from arrays without a ROS graph."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA, Float64MultiArray, MultiArrayDimension
from visualization_msgs.msg import Marker, MarkerArray

from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.frames import Array
from robot_calib.messages import TRACKER_FRAME

AXIS_LENGTH_M = 0.3  # drawn length of an identified joint axis, centred on its circles
CIRCLE_SEGMENTS = 72
RESIDUAL_FIELDS = "x,y,z,residual"  # the columns of ~/residuals (msgs_doc/calibrator.md)


def residuals_message(measured: Array, residuals: Array) -> Float64MultiArray:
    """~/residuals: rows [x, y, z, |r|] of the measured points (n, 3) [m, tracker frame] and
    the norms of the residuals (n, 3) predicted - measured [m], row-major, dims [n, 4]."""
    table = np.column_stack([measured, np.linalg.norm(residuals, axis=1)])
    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label="measurement", size=table.shape[0], stride=table.size),
        MultiArrayDimension(label=RESIDUAL_FIELDS, size=4, stride=4),
    ]
    msg.layout.data_offset = 0
    msg.data = table.ravel().tolist()
    return msg


def _points(xyz: Array | Sequence[Array]) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in xyz]


def _marker(ns: str, marker_id: int, kind: int, rgba: tuple[float, ...]) -> Marker:
    marker = Marker(ns=ns, id=marker_id, type=kind, action=Marker.ADD)
    marker.header.frame_id = TRACKER_FRAME  # stamp 0: RViz uses the latest transform
    marker.pose.orientation.w = 1.0
    marker.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    return marker


def circle_polyline(centre: Array, normal: Array, radius: float, n: int) -> Array:
    """Closed polyline (n + 1, 3) of the circle of `centre` (3,) [m], unit `normal` (3,),
    `radius` [m]: first point repeated last."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    angle = np.linspace(0.0, 2 * np.pi, n + 1)
    return centre + radius * (np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v)


def calibration_markers(cal: Calibration, measured: Array, residual_scale: float) -> MarkerArray:
    """~/markers in the tracker frame: a DELETEALL (clears an earlier result), then namespace
    "axes" (one ARROW per identified joint axis, id = joint), "circles" (one LINE_STRIP per
    fitted sweep circle), "measured" (SPHERE_LIST of the points) and "residuals" (LINE_LIST
    from each measured point towards its prediction, `residual_scale` times the residual)."""
    markers = [Marker(action=Marker.DELETEALL)]
    markers[0].header.frame_id = TRACKER_FRAME
    if cal.cpa is not None:
        for j, axis in enumerate(cal.cpa.axes, start=1):
            arrow = _marker("axes", j, Marker.ARROW, (0.1, 0.4, 1.0, 1.0))
            half = 0.5 * AXIS_LENGTH_M * axis.direction
            arrow.points = _points([axis.point - half, axis.point + half])
            arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.004, 0.010, 0.020  # shaft, head [m]
            markers.append(arrow)
        for k, sweep in enumerate(cal.cpa.sweeps):
            strip = _marker("circles", k, Marker.LINE_STRIP, (0.2, 0.8, 0.2, 1.0))
            c = sweep.circle
            strip.points = _points(circle_polyline(c.centre, c.normal, c.radius, CIRCLE_SEGMENTS))
            strip.scale.x = 0.001  # line width [m]
            markers.append(strip)
    dots = _marker("measured", 0, Marker.SPHERE_LIST, (1.0, 1.0, 1.0, 1.0))
    dots.points = _points(measured)
    dots.scale.x = dots.scale.y = dots.scale.z = 0.003  # sphere diameter [m]
    lines = _marker("residuals", 0, Marker.LINE_LIST, (1.0, 0.2, 0.1, 1.0))
    ends = measured + residual_scale * cal.residuals
    lines.points = _points(np.stack([measured, ends], axis=1).reshape(-1, 3))
    lines.scale.x = 0.0005  # line width [m]
    markers += [dots, lines]
    return MarkerArray(markers=markers)
