"""PNG of a linkage's structural scheme (matplotlib, no display needed): the frame's pivots, the driving link and
each Assur group in its own colour, with the joints and links named and W written out."""

from __future__ import annotations

import cmath
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from mech_regulator.mechanisms.linkage import Dyad, Linkage, Structure, solve  # noqa: E402
from mech_regulator.mechanisms.linkage.cam import cam_pairs  # noqa: E402
from mech_regulator.mechanisms.linkage.drawing import BLOCK_PER_CRANK, crank_length, link_polygon, pitch_circles  # noqa: E402
from mech_regulator.mechanisms.linkage.gears import GearGroup  # noqa: E402

FRAME_COLOUR, CRANK_COLOUR = "0.45", "black"
GROUP_COLOURS = plt.rcParams["axes.prop_cycle"].by_key()["color"]


def plot_structure(linkage: Linkage, structure: Structure, phi: float, title: str, path: Path) -> None:
    """The scheme at crank angle phi [rad]: links as thick polylines (a link of three or more joints shaded),
    sliders as blocks on their guides (dashed, in the guide's colour), revolute joints as rings, the frame's as
    rings on a hatched base, gears as their pitch circles (dash-dotted, with the radius to the link's x axis) and
    each mesh named at its pitch point, coloured by role: frame grey, driving link black, group k the k-th colour;
    a cam as its profile (turned to phi, in the driving link's colour) with its roller's circle and the contact
    marked."""
    poses = solve(linkage, structure, phi, derivatives=False)
    colour = {linkage.frame: FRAME_COLOUR, linkage.crank: CRANK_COLOUR}
    labels = {linkage.crank: f"driving link: {linkage.crank}"}
    for number, group in enumerate(structure.groups, start=1):
        for link in group.links:
            colour[link] = GROUP_COLOURS[(number - 1) % len(GROUP_COLOURS)]
        kind = (
            f"class II {group.kind}"
            if isinstance(group, Dyad)
            else f"gear about {group.pivot.name}"
            if isinstance(group, GearGroup)
            else group.kind
        )
        labels[group.links[0]] = f"group {number}: {kind} ({' + '.join(group.links)})"
    figure, axes = plt.subplots(figsize=(9, 7), constrained_layout=True)
    cams = cam_pairs(linkage, structure.groups, None)
    size = max([crank_length(linkage)] + [pair.pitch_radius for pair in cams])
    for pair in cams:
        _draw_cam(axes, pair, phi, poses, colour)
    for name in linkage.moving_links():
        points = np.array([[p.real, p.imag] for p in link_polygon(linkage, poses, name)])
        axes.plot(
            points[:, 0],
            points[:, 1],
            color=colour[name],
            lw=3.5,
            solid_capstyle="round",
            label=labels.get(name),
            zorder=2,
        )
        if len(points) > 3:
            axes.fill(points[:, 0], points[:, 1], color=colour[name], alpha=0.15, zorder=1)
        # the name below the middle of the link's longest side, or below a block (a link whose points coincide)
        sides = [(np.hypot(*(b - a)), a, b) for a, b in zip(points, points[1:])]
        length, start, end = max(sides, key=lambda side: side[0]) if sides else (0.0, points[0], points[0])
        where, offset = (0.5 * (start + end), (0, -14)) if length > 1e-9 * size else (points[0], (10, -24))
        axes.annotate(
            name,
            where,
            color=colour[name],
            fontsize=9,
            fontstyle="italic",
            xytext=offset,
            textcoords="offset points",
            ha="center",
        )
    for link, centre, radius, theta in pitch_circles(linkage, structure, poses):
        ring = centre + radius * np.exp(1j * (theta + np.linspace(0.0, 2.0 * np.pi, 145)))
        axes.plot(ring.real, ring.imag, "-.", color=colour[link], lw=1.5, zorder=2)
        tick = [centre, centre + radius * cmath.exp(1j * theta)]
        axes.plot([p.real for p in tick], [p.imag for p in tick], color=colour[link], lw=1.0, zorder=2)
    names_at: dict[tuple[float, float], list[str]] = {}
    for group in structure.groups:  # a mesh is named at its pitch point, O_a + rho_a u
        if isinstance(group, GearGroup):
            a, b = (
                poses[link][0] + linkage.link(link).points[centre] * cmath.exp(1j * poses[link][1])
                for link, centre in zip(group.mesh.links, group.mesh.gear_mesh().centres)
            )
            pitch = a + group.pitch[0] * (b - a) / abs(b - a)
            axes.plot(pitch.real, pitch.imag, "D", ms=5, color="black", zorder=4)
            names_at.setdefault((round(pitch.real, 9), round(pitch.imag, 9)), []).append(group.mesh.name)
    for joint in (joint for joint in linkage.joints if joint.kind not in ("cam", "gear")):
        guide, slider = joint.links
        where = poses[slider][0] + linkage.link(slider).points[joint.name] * cmath.exp(1j * poses[slider][1])
        if joint.kind == "prismatic":
            along = cmath.exp(1j * (joint.direction + poses[guide][1]))
            ends = [where - 1.5 * size * along, where + 1.5 * size * along]
            axes.plot([e.real for e in ends], [e.imag for e in ends], "--", color=colour[guide], lw=1.2, zorder=1)
            half = 0.5 * BLOCK_PER_CRANK * size
            corners = [where + half * along * complex(x, 0.5 * y) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            axes.fill(
                [c.real for c in corners],
                [c.imag for c in corners],
                facecolor="white",
                edgecolor=colour[slider],
                lw=2.0,
                zorder=3,
            )
        else:
            if linkage.frame in joint.links:
                axes.plot(where.real, where.imag - 0.12 * size, marker=(3, 0, 0), ms=14, color=FRAME_COLOUR, zorder=2)
            axes.plot(where.real, where.imag, "o", ms=7, mfc="white", mec="black", zorder=4)
        names_at.setdefault((round(where.real, 9), round(where.imag, 9)), []).append(joint.name)
    for (x, y), names in names_at.items():  # joints at one place (a pin and its slider) share one label
        axes.annotate(
            ", ".join(names),
            (x, y),
            fontsize=10,
            fontweight="bold",
            xytext=(5, 5),
            textcoords="offset points",
            zorder=5,
        )
    axes.set(
        aspect="equal",
        xlabel="x [m]",
        ylabel="y [m]",
        title=f"{title}: structure at phi = {np.degrees(phi):g} deg\n{structure.formula()}",
    )
    axes.grid(alpha=0.25)
    axes.legend(loc="best", fontsize=8)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _draw_cam(axes, pair, phi: float, poses: dict, colour: dict) -> None:
    """A cam's profile turned to crank angle phi [rad], filled in its link's colour, the roller's circle (if any)
    and the contact point with the cam pair's name."""
    cam = pair.group.pair.links[0]
    outline = pair.centre + pair.profile() * cmath.exp(1j * phi)
    outline = np.append(outline, outline[:1])
    axes.fill(outline.real, outline.imag, color=colour[cam], alpha=0.12, zorder=1)
    axes.plot(outline.real, outline.imag, color=colour[cam], lw=2.0, zorder=2)
    motion = pair.motion(phi)
    centre = complex(motion.P[0])
    if pair.roller_radius > 0.0:
        circle = centre + pair.roller_radius * np.exp(1j * np.linspace(0.0, 2.0 * np.pi, 73))
        axes.plot(circle.real, circle.imag, color=colour[pair.group.roller], lw=2.0, zorder=3)
    contact = complex(pair.contact_point(phi)[0])
    axes.plot(contact.real, contact.imag, "o", ms=5, color="black", zorder=4)
    axes.annotate(
        pair.group.pair.name,
        (contact.real, contact.imag),
        fontsize=10,
        fontweight="bold",
        xytext=(6, -14),
        textcoords="offset points",
        zorder=5,
    )
