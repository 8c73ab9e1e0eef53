"""A general planar linkage (docs/linkages.md): its data model, structural analysis (source 001: degrees of freedom,
repeated and redundant constraints, passive freedoms, the driving link and class-II Assur groups), the closed-form
position of each dyad type with its analytic velocity and acceleration ratios, and its reduction to the crank
(J(phi), dJ/dphi, the links' weight moment, the output coordinate) in the `reduced(phi)` contract of
mechanisms/__init__.py, and the kinetostatics by groups (joint reactions from the farthest group inward, the
balancing moment). Pure math and numpy: no ROS, no Rerun. docs/linkages.md describes the method.
"""

from mech_regulator.mechanisms.linkage.groups import Dyad, RedundantLink
from mech_regulator.mechanisms.linkage.kinematics import assembly_failures, make_point_motions, make_reduced, solve
from mech_regulator.mechanisms.linkage.kinetostatics import LinkageLoads, make_joint_loads, make_kinetostatics
from mech_regulator.mechanisms.linkage.model import CAM, PRISMATIC, REVOLUTE, Joint, Link, Linkage, LinkageError
from mech_regulator.mechanisms.linkage.structure import Structure, analyse, checked

__all__ = [
    "CAM",
    "PRISMATIC",
    "REVOLUTE",
    "Dyad",
    "Joint",
    "Link",
    "Linkage",
    "LinkageError",
    "RedundantLink",
    "LinkageLoads",
    "Structure",
    "analyse",
    "assembly_failures",
    "checked",
    "make_joint_loads",
    "make_kinetostatics",
    "make_point_motions",
    "make_reduced",
    "solve",
]
