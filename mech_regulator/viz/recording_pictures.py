"""The pictures of a run's recording (viz/recording.py): the colours, the mechanism and the governor drawn in
Rerun's 2-D views (their parts' styles, the fixed parts logged once, the moving parts' frames as columns), and which
mechanism is drawn. Rerun's 2-D views have y pointing down, so the drawings (y up, mechanisms.drawing and
governors.drawing) are flipped on the way in."""

from __future__ import annotations

import numpy as np
import rerun as rr

from mech_regulator.mechanisms.drawing import mechanism_kind
from mech_regulator.model import MachineModel
from mech_regulator.scene import mechanism_keys

WHITE, GREY, DARK_GREY = (235, 235, 235), (150, 150, 150), (95, 95, 95)
BLUE, ORANGE, GREEN = (80, 160, 255), (255, 165, 50), (110, 215, 110)
RED, VIOLET, YELLOW, PINK = (255, 95, 95), (195, 125, 255), (250, 210, 60), (255, 120, 190)

COLOUR_NAMES = {
    WHITE: "white",
    BLUE: "blue",
    ORANGE: "orange",
    GREEN: "green",
    RED: "red",
    VIOLET: "violet",
    YELLOW: "yellow",
    PINK: "pink",
}


# drawing part -> (colour, line width or point radius [ui points]; None: the point radius is in metres)
MECHANISM_STYLE = {
    "guide": (GREY, 1.5),
    "frame": (GREY, 2.0),
    "crank_path": (DARK_GREY, 1.0),
    "disc": (GREY, 1.5),
    "crank": (ORANGE, 3.0),
    "spoke": (ORANGE, 3.0),
    "rod": (BLUE, 3.0),
    "coupler": (BLUE, 3.0),
    "rocker": (GREEN, 3.0),
    "slider": (WHITE, 2.0),
    "joints": (WHITE, 4.0),
    "tie": (VIOLET, 2.5),
    "side": (PINK, 2.5),
    "shuttle": (YELLOW, 4.0),
    "links": (BLUE, 3.0),
    "sliders": (WHITE, 2.0),
    "gears": (GREEN, 1.5),
}


GOVERNOR_STYLE = {
    "spindle": (GREY, 2.5),
    "stops": (RED, 2.5),
    "upper_arms": (ORANGE, 2.5),
    "lower_links": (BLUE, 2.0),
    "sleeve": (YELLOW, 2.0),
    "balls": ((200, 200, 215), None),
    "spindle_mark": (ORANGE, 4.0),
}


POINT_PARTS = ("joints", "balls", "spindle_mark")


FLIP_Y = np.array([1.0, -1.0])  # drawings have y up, Rerun's 2-D views y down


MECHANISM_NAMES = {
    "crank_slider": "crank–slider",
    "four_bar": "four-bar linkage",
    "walking_beam": "walking beam",
    "linkage": "linkage",
}


def drawn_mechanism(model: MachineModel) -> tuple[mechanism_keys.Mechanism | None, bool]:
    """The mechanism the recording draws and whether it is the driven part's (turning at phi - twist behind a
    coupling): the machine's own, else the one behind a coupling, else None (a schematic disc)."""
    return model.scene.machine.analysed_mechanism()


def mechanism_title(model: MachineModel) -> str:
    """Name of the mechanism view: what it draws."""
    drawing, driven = drawn_mechanism(model)
    kind = mechanism_kind(drawing)
    if kind is None:
        return "crank angle φ (no mechanism: a disc and a spoke)"
    name = MECHANISM_NAMES[kind]
    cylinders = getattr(drawing, "cylinders", None)
    if cylinders:
        name += f", cylinder 1 of {len(cylinders)}"
    return f"driven {name} at φ₂ = φ − twist" if driven else name


def log_drawing(
    stream: rr.RecordingStream,
    root: str,
    outline: dict[str, np.ndarray],
    styles: dict,
    moving,
    ball_radius: float | None = None,
) -> None:
    """Log on `stream` the fixed parts of a drawing (metres, y up) whole and static under root/<part>, y flipped,
    and the moving parts' colours and sizes static (their geometry comes frame by frame); ball_radius [m]: the
    size of the points whose style gives none (a governor's balls)."""
    for name, part in outline.items():
        colour, size = styles[name]
        geometry = part * FLIP_Y if name not in moving else None
        archetype: rr.Points2D | rr.LineStrips2D
        if name in POINT_PARTS:
            radius = ball_radius if size is None else rr.Radius.ui_points(size)
            archetype = rr.Points2D.from_fields(positions=geometry, radii=radius, colors=colour, draw_order=40.0)
        else:
            strips = None if geometry is None else list(geometry) if geometry.ndim == 3 else [geometry]
            archetype = rr.LineStrips2D.from_fields(
                strips=strips,
                radii=rr.Radius.ui_points(0.5 * size),
                colors=colour,
                draw_order=30.0 if name in moving else 10.0,
            )
        stream.log(f"{root}/{name}", archetype, static=True)


def frame_columns(part: str, frames: list[np.ndarray]):
    """The animation frames of a drawing's moving part (y down) as Rerun columns partitioned by frame: Points2D (a
    set of points per frame) for a part of POINT_PARTS, else LineStrips2D (one or a bundle of strips per frame).

    The strips go to Rerun as one array (strips x points x 2) when they all have as many points, as every bundled
    drawing's do: given as a list of one small array per strip, Rerun's conversion cost 1 s and left some 45 MB of
    the C heap free but not given back for a send of 10 000 frames of a bundle of 4 strips, which the recorder's
    resident memory kept from then on (docs/ros.md, "The recorder's memory"); the column is the same either way."""
    if part in POINT_PARTS:
        columns = rr.Points2D.columns(positions=np.concatenate(frames))
        lengths = [len(frame) for frame in frames]
    else:
        bundles = [frame if frame.ndim == 3 else frame[np.newaxis] for frame in frames]
        lengths = [len(bundle) for bundle in bundles]
        if len({bundle.shape[1] for bundle in bundles}) == 1:
            columns = rr.LineStrips2D.columns(strips=np.concatenate(bundles))
        else:
            columns = rr.LineStrips2D.columns(strips=[strip for bundle in bundles for strip in bundle])
    return columns.partition(lengths)
