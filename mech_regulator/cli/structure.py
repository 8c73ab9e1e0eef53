"""`mech-regulator structure SCENE`: the structural analysis of a linkage scene (source 001, chapter 1) printed,
as JSON, and drawn with its groups coloured (viz/structure_plot.py)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_structure_command(scene_command) -> None:
    """Add the `structure` subcommand (scene_command: parser.build_parser's helper)."""
    structure = scene_command(
        "structure",
        "structural analysis of a linkage scene (source 001): moving links n, "
        "lower and higher pairs p5, p4, the degrees of freedom W with the "
        "repeated and redundant constraints and passive freedoms found, the "
        "driving link and the Assur groups with their class and type",
    )
    structure.add_argument("--plot", type=Path, help="write a PNG picture of the scheme with the groups coloured")
    structure.add_argument("--json", action="store_true", help="print the analysis as JSON")


def run_structure(scene, args: argparse.Namespace) -> int:
    """structure: the analysis of the scene's linkage (the machine's, else the driven part's behind a coupling);
    a scene whose linkage has W != 1 or an unsupported group has already been refused (mechanisms/checks.py)."""
    from mech_regulator.cli.report.data import to_json
    from mech_regulator.cli.report.outputs import OutputWriter
    from mech_regulator.cli.report.terminal import terminal_text
    from mech_regulator.mechanisms import cam_pairs_of, mechanism_geometry
    from mech_regulator.mechanisms.linkage import Dyad, RedundantLink
    from mech_regulator.scene import SceneError

    mechanism = scene.machine.analysed_mechanism()[0]
    if mechanism is None or mechanism.type != "linkage":
        raise SceneError(
            f"scene '{scene.name}' has mechanism {mechanism.type if mechanism else 'none'}: structure "
            "analyses machine.mechanism.type: linkage (links, joints, crank; docs/linkages.md)"
        )
    linkage, structure = mechanism_geometry(mechanism)
    cams = cam_pairs_of(mechanism, scene.machine.gravity)
    groups = [
        {
            "number": number,
            "type": group.kind,
            "class": "II"
            if isinstance(group, Dyad)
            else "redundant"
            if isinstance(group, RedundantLink)
            else group.kind,  # "gear" or "cam follower"
            "links": list(group.links),
            "joints": [joint.name for joint in group.joints],
            "branch": getattr(group, "branch", None),
        }
        for number, group in enumerate(structure.groups, start=1)
    ]
    summary = {
        "scene": scene.name,
        "n": structure.moving_links,
        "p5": structure.lower_pairs,
        "p4": structure.higher_pairs,
        "W": structure.freedom,
        "formula": structure.formula(),
        "repeated": list(structure.repeated),
        "redundant": list(structure.redundant),
        "passive": list(structure.passive),
        "driving_link": linkage.crank,
        "groups": groups,
        "cams": [pair.numbers() for pair in cams],
    }
    outputs = OutputWriter(summary)
    if args.plot is not None:
        from mech_regulator.viz.structure_plot import plot_structure

        outputs.write(
            "plot",
            args.plot,
            lambda path: plot_structure(linkage, structure, scene.scenario.initial.phi, scene.name or "linkage", path),
        )
    if args.json:
        print(to_json(summary))
    else:
        print(
            terminal_text(
                f"scene {scene.name}: linkage, driving link {linkage.crank} (turns about "
                f"{linkage.crank_pivot().name} with the frame)"
            )
        )
        print(terminal_text("\n".join(structure.report() + [line for pair in cams for line in pair.report()])))
        if "plot" in summary:
            print(terminal_text(f"wrote {args.plot}"))
    return outputs.exit_code(0)
