"""Drawing geometry of a scene's mechanism: the links as 2-D polylines at a crank angle (pure numpy).

Coordinates are metres in the mechanism plane with y UP and the crank axis at the origin (the
conventions of docs/scenes.md). An outline is a dict of named parts; each part is either one polyline,
shape (n, 2), or a bundle of k polylines of n points, shape (k, n, 2). The part named `joints` is a
set of points (the revolute joints), shape (n, 2). Which parts move with phi is listed in
MOVING_PARTS; the others (guide, frame, path of the crank pin, disc) stay where they are.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from mech_regulator.mechanisms import crank_slider, four_bar, walking_beam
from mech_regulator.mechanisms.linkage import drawing as linkage_drawing
from mech_regulator.mechanisms.linkage.drawing import circle
from mech_regulator.scene import mechanism_keys

BLOCK_LENGTH_PER_CRANK = 1.0  # slider block length along the guide, per crank radius [-]
BLOCK_HEIGHT_PER_CRANK = 0.6  # slider block height across the guide, per crank radius [-]
DISC_RADIUS = 1.0  # radius of the schematic disc of a machine without mechanism [m]
BOUNDS_MARGIN = 0.08  # margin around the swept outline, per its larger span [-]
BOUNDS_SAMPLES = 360  # crank angles sampled over a turn to find the swept outline [-]

MOVING_PARTS = {
    "crank_slider": ("crank", "rod", "slider", "joints"),
    "four_bar": ("crank", "coupler", "rocker", "joints"),
    "walking_beam": ("crank", "coupler", "rocker", "tie", "side", "shuttle", "joints"),
    "linkage": linkage_drawing.MOVING_PARTS,
    None: ("spoke", "joints"),
}


def mechanism_kind(mechanism_spec: mechanism_keys.Mechanism | None) -> str | None:
    """'crank_slider', 'four_bar', 'walking_beam', 'linkage', or None for a machine without a mechanism."""
    return None if mechanism_spec is None else mechanism_spec.type


def rectangle(centre: tuple[float, float], half_width: float, half_height: float) -> np.ndarray:
    """Closed polyline of an axis-aligned rectangle around centre [m], shape (5, 2)."""
    x, y = centre
    return np.array(
        [
            [x - half_width, y - half_height],
            [x + half_width, y - half_height],
            [x + half_width, y + half_height],
            [x - half_width, y + half_height],
            [x - half_width, y - half_height],
        ]
    )


def mechanism_outline(mechanism_spec: mechanism_keys.Mechanism | None, phi: float) -> dict[str, np.ndarray]:
    """The mechanism's parts at crank angle phi [rad], in metres with y up.

    Crank–slider (crank R, rod l, offset e): crank O-B with the pin B = R (cos phi, sin phi), rod B-C with
    the slider C = (x, e), x from `crank_slider.slider_kinematics`; a slider block (rectangle
    BLOCK_LENGTH_PER_CRANK R by BLOCK_HEIGHT_PER_CRANK R around C); the guide y = e from the inner dead
    centre x = sqrt((l - R)^2 - e^2) to the outer one x = sqrt((l + R)^2 - e^2), extended by half a block;
    the path of the pin (circle of radius R).
    Four-bar (a, b, c, d, th1): crank A-B with A = 0, B = a e^{i phi}; coupler B-C; rocker D-C with
    D = d e^{i th1}, C = D + c e^{i th4}, th4 from `four_bar.link_angles` on the scene's branch; the frame
    A-D; the path of the pin B.
    Walking beam (source 004's names, `walking_beam.solve`): crank O1-A, coupler triangle A-B-C, the two
    rockers O2-B and O3-E (a bundle), the tie B-E, the side link E-D, the shuttle bar C-D, the frame O1-O2-O3
    and the path of the pin A.
    Linkage: the parts of `linkage.drawing.linkage_outliner` (frame, crank, links, sliders, gears, joints).
    No mechanism: a disc of radius DISC_RADIUS (schematic: the machine has no link lengths) and a spoke
    from its centre to DISC_RADIUS (cos phi, sin phi).
    """
    if isinstance(mechanism_spec, mechanism_keys.CrankSlider):
        return _crank_slider_outline(mechanism_spec, phi)
    if isinstance(mechanism_spec, mechanism_keys.FourBar):
        return _four_bar_outline(mechanism_spec, phi)
    if isinstance(mechanism_spec, mechanism_keys.WalkingBeam):
        return _walking_beam_outline(mechanism_spec, phi)
    if isinstance(mechanism_spec, mechanism_keys.Linkage):
        return _linkage_outliner(mechanism_spec)(phi)
    tip = (DISC_RADIUS * math.cos(phi), DISC_RADIUS * math.sin(phi))
    return {
        "disc": circle((0.0, 0.0), DISC_RADIUS),
        "spoke": np.array([[0.0, 0.0], tip]),
        "joints": np.array([[0.0, 0.0]]),
    }


_last_linkage: list = [None, None]  # the linkage spec drawn last and its outliner (linkage_drawing.linkage_outliner)


def _linkage_outliner(spec: mechanism_keys.Linkage) -> Callable[[float], dict[str, np.ndarray]]:
    """The outline at phi of a linkage's spec (linkage_drawing.linkage_outliner), made once for the spec drawn last:
    a recording draws one mechanism at every frame, and its geometry (mechanisms.mechanism_geometry: the Assur
    groups, a gear's pitch checked at sample angles), pose solver and cam profiles took 0.3-1.4 ms a frame on the
    bundled linkages (the geared shaker's recorder through the nodes fell minutes behind its machine on it). A scene
    section is frozen: the same object is the same spec."""
    if _last_linkage[0] is not spec:
        from mech_regulator.mechanisms import mechanism_geometry

        _last_linkage[:] = [spec, linkage_drawing.linkage_outliner(*mechanism_geometry(spec))]
    return _last_linkage[1]


def _crank_slider_outline(spec: mechanism_keys.CrankSlider, phi: float) -> dict[str, np.ndarray]:
    R, rod, e = spec.crank, spec.rod, spec.offset
    pin = (R * math.cos(phi), R * math.sin(phi))
    x = crank_slider.slider_kinematics(phi, R, rod, e)[0]
    half_block = 0.5 * BLOCK_LENGTH_PER_CRANK * R
    inner = math.sqrt((rod - R) ** 2 - e * e)
    outer = math.sqrt((rod + R) ** 2 - e * e)
    return {
        "guide": np.array([[inner - half_block, e], [outer + half_block, e]]),
        "crank_path": circle((0.0, 0.0), R),
        "crank": np.array([[0.0, 0.0], pin]),
        "rod": np.array([pin, [x, e]]),
        "slider": rectangle((x, e), half_block, 0.5 * BLOCK_HEIGHT_PER_CRANK * R),
        "joints": np.array([[0.0, 0.0], pin, [x, e]]),
    }


def _four_bar_outline(spec: mechanism_keys.FourBar, phi: float) -> dict[str, np.ndarray]:
    a, b, c, d = spec.crank, spec.coupler, spec.rocker, spec.frame
    th1 = math.radians(spec.frame_angle_deg)
    th4 = four_bar.link_angles(phi, a, b, c, d, th1, four_bar.BRANCH_SIGN[spec.branch])[3]
    A = (0.0, 0.0)
    B = (a * math.cos(phi), a * math.sin(phi))
    D = (d * math.cos(th1), d * math.sin(th1))
    C = (D[0] + c * math.cos(th4), D[1] + c * math.sin(th4))
    return {
        "frame": np.array([A, D]),
        "crank_path": circle(A, a),
        "crank": np.array([A, B]),
        "coupler": np.array([B, C]),
        "rocker": np.array([D, C]),
        "joints": np.array([A, B, C, D]),
    }


def _walking_beam_outline(spec: mechanism_keys.WalkingBeam, phi: float) -> dict[str, np.ndarray]:
    geometry = walking_beam.geometry_from_scene(spec)
    points = {name: motion[0] for name, motion in walking_beam.solve(phi, geometry)[1].items()}
    points["O1"] = 0j
    points["O2"] = geometry.frame * np.exp(1j * geometry.frame_angle)
    points["O3"] = points["O2"] + walking_beam.beam(geometry)

    def line(*names: str) -> np.ndarray:
        return np.array([[points[name].real, points[name].imag] for name in names])

    return {
        "frame": line("O1", "O2", "O3"),
        "crank_path": circle((0.0, 0.0), geometry.crank),
        "crank": line("O1", "A"),
        "coupler": line("A", "B", "C", "A"),
        "rocker": np.stack([line("O2", "B"), line("O3", "E")]),
        "tie": line("B", "E"),
        "side": line("E", "D"),
        "shuttle": line("C", "D"),
        "joints": line("O1", "A", "B", "C", "D", "E", "O2", "O3"),
    }


def outline_extent(
    outlines: list[dict[str, np.ndarray]], point_radius: float = 0.0
) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) [m] of every part of every outline; points (parts of shape (n, 2) whose
    name says `joints` or `balls`) are grown by point_radius; an empty part (a linkage without sliders has no
    slider blocks) adds nothing."""
    lows, highs = [], []
    for outline in outlines:
        for name, part in outline.items():
            points = part.reshape(-1, 2)
            if not len(points):
                continue
            grow = point_radius if name in ("joints", "balls") else 0.0
            lows.append(points.min(axis=0) - grow)
            highs.append(points.max(axis=0) + grow)
    low, high = np.min(lows, axis=0), np.max(highs, axis=0)
    return float(low[0]), float(high[0]), float(low[1]), float(high[1])


def with_margin(
    extent: tuple[float, float, float, float], margin: float = BOUNDS_MARGIN
) -> tuple[float, float, float, float]:
    """extent (xmin, xmax, ymin, ymax) [m] grown on every side by margin times its larger span."""
    xmin, xmax, ymin, ymax = extent
    pad = margin * max(xmax - xmin, ymax - ymin)
    return xmin - pad, xmax + pad, ymin - pad, ymax + pad


def mechanism_bounds(mechanism_spec: mechanism_keys.Mechanism | None) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) [m, y up] framing the mechanism over a whole turn: the extent of its
    outline at BOUNDS_SAMPLES crank angles, grown by BOUNDS_MARGIN of the larger span on every side."""
    angles = np.linspace(0.0, 2.0 * math.pi, BOUNDS_SAMPLES, endpoint=False)
    return with_margin(outline_extent([mechanism_outline(mechanism_spec, phi) for phi in angles]))
